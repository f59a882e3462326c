"""The radar service: Continental ARS408-21 on any python-can bus to confirmed tracks on Zenoh.

See docs/radar.md. Modules: `ars408` (CAN database, decoder, encoder), `cycle` (cycle
assembly), `detections` (decode, prefilter, merge), `tracker` (Kalman), `core` (one
radar's pure pipeline), `configure` (0x200 write and confirmation), `ego` (0x300/0x301),
`can_io` (buses and log replay), `can_links` (the radar side of a CAN link, for tests and
the simulator), `service` (the I/O shell), `main` (`aeb radar`).
"""
