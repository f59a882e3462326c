"""The closed-loop scenario simulator (A SIMULATION of the vehicle, the radar, the camera
and the road; the real paths are the services' CAN, camera and serial inputs).

Pure parts: `scenario` (data files), `world` (ego and object kinematics, collisions),
`radar_model` (what an ARS408 would report), `render` (camera frames), `verdict`; the
ground truth it publishes on `sim/world` is tools/messages.py, its key tools/keys.py.
Shells: `radar_feed` (CAN frames on a python-can bus), `camera_source` (the camera
service's synthetic-source plugin), `actuator` (the brake actuator on a serial port,
`aeb sim-actuator`) with `pty_pair`, `runner` (the real-time closed loop), `plot`.
"""
