"""Foxglove: the views of the stack's messages, shared by recordings and the live bridge."""
