"""Fault injection (`aeb faults`) and fuzzing (`aeb faults fuzz`) of the stack, and the
SIMULATED attacker its intruder fault runs (intruder)."""
