"""`aeb up`: the process table, the restart policy, the process supervisor and the
command (main)."""
