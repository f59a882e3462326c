"""The vehicle gateway: the car's own CAN decoded through its DBC (cantools) to the
vehicle's state on Zenoh: `vehicle/motion` (EgoMotion: speed, yaw rate) and
`vehicle/driver` (DriverInputs: steering wheel, pedals, gear), each at its rate and only
while fresh, and the gateway's status.

See docs/vehicle.md. Modules: `mapping` (the config resolved against the DBC: which
frames carry which signals, and the unit conversions), `dbc` (reading the DBC file),
`core` (the pure core, `VehicleCore`), `shell` (the I/O shell, `VehicleShell`), `main`
(`aeb vehicle`).
"""
