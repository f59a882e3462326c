"""The radar service: Continental ARS408-21 on any python-can bus to confirmed tracks on Zenoh.

See docs/radar.md. Modules: `ars408` (CAN database, decoder, encoder, transmissions),
`assembly` (a radar cycle's frames into one RawCycle), `detections` (decode, prefilter,
merge), `neighbours` (near pairs), `tracker` (Kalman), `core` (one radar's pure
pipeline, `RadarCore`), `configure` (0x200 write and confirmation), `ego` (0x300/0x301),
`ports` (its frames as python-can messages, the bus opened or a log replayed), `shell`
(the I/O shell, `RadarShell`), `main` (`aeb radar`).
"""
