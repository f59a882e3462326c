"""The car's DBC file, read with cantools."""

import cantools.database

from aeb_radar_camera.services.vehicle.mapping import Database, MappingError


def load_dbc(path: str) -> Database:
    """The CAN database in `path` (a DBC; cantools reads KCD, SYM, ARXML too). Raises
    MappingError when it cannot be read or is not a CAN database."""
    try:
        db = cantools.database.load_file(path)
    except OSError as exc:
        raise MappingError(f"gateway.dbc {path!r}: {exc.strerror or exc}") from exc
    except (cantools.database.UnsupportedDatabaseFormatError, ValueError, KeyError,
            IndexError, TypeError, UnicodeDecodeError) as exc:
        raise MappingError(f"gateway.dbc {path!r} is not a CAN database cantools reads: "
                           f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                           ) from exc
    if not isinstance(db, Database):
        raise MappingError(f"gateway.dbc {path!r} is a diagnostics database, not CAN")
    return db
