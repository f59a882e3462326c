"""`aeb foxglove`: the live bus in Foxglove, with the views a recording derives
(tools/recording/foxglove_views.py)."""
