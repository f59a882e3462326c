"""`aeb ab-report`: where a primary and a candidate fusion instance disagreed."""
