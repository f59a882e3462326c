"""`aeb calib-check` (check.py: projected tracks drawn over a frame) and `aeb calib-capture`
(capture.py: a frame and its nearest radar cycle saved from the live bus)."""
