"""Command-line entry points (`aeb`, tools/cli.py) and what they are made of; the order
in which its packages may import each other is in docs/architecture.md (Shape of tools/)."""
