"""The closed loop in lockstep, for running many scenarios (the test grid): the services'
pure cores (radar, the camera's encoding, fusion, brake) in one process on a SIMULATED
clock, with the simulator's world, radar, camera and actuator. A SIMULATION of the
vehicle, its sensors, its actuator and the links between the services.

`lockstep` runs one scenario (`run_scenario`), `pool` many in parallel processes; the
loop's parts: `clock` (the simulated clock and its events), `delays` (the modelled
transport and processing times), `radar`, `camera`, `brake` (each service's core with
its simulated sensor or actuator), `profile` (where the wall time goes).
"""
