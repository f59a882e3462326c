"""Generic views of any key on the bus: `aeb echo` (decoded messages) and `aeb hz` (rates)."""
