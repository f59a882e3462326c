"""Where the files shipped with the package are, in a checkout and in an installed wheel
alike: `deploy/` (example service configs, calibration, process tables, Zenoh and systemd
files, the bundled ARS408 recording) sits beside `common/` in both, because the wheel
ships it as package data.

Commands use these paths for their defaults; a vehicle's own copy is made with
`aeb init DIR` and named on the command line.
"""

from pathlib import Path

DEPLOY = Path(__file__).resolve().parent.parent / "deploy"
EXAMPLE_CALIBRATION = DEPLOY / "calibration" / "d435_848x480.toml"
EXAMPLE_KEYS = DEPLOY / "keys"   # INSECURE example command keys: demo and simulator only
SINGLE_HOST_TABLE = DEPLOY / "single-host.toml"
ARS408_RECORDING = DEPLOY / "recordings" / "ars408" / "candump-2026-06-24_154259.log"

# the ARS408-21 DBC rendered from the radar's signal table (services/radar/ars408/dbc.py):
# found without importing the radar (and numpy), for `aeb can-export`
ARS408_DBC = DEPLOY.parent / "services" / "radar" / "ars408" / "ars408_21.dbc"
