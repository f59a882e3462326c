"""Shared contract of the AEB stack: messages, keys, configuration, Zenoh access, clocks."""
