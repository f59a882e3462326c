"""Brake service: BrakeCommands of one fusion instance to a brake-by-wire actuator over
serial, with a deadline-miss fail-safe (docs/brake.md, docs/actuator-protocol.md)."""
