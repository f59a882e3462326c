"""Fault injection (`aeb faults`) and fuzzing (`aeb faults fuzz`) of the stack."""
