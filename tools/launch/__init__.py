"""`aeb up`: the process table, the restart policy and the process supervisor."""
