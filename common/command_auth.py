"""Authenticated BrakeCommands: key files, signing (fusion) and MAC checks (brake).

A command key belongs to one fusion instance. Fusion signs every BrakeCommand with it;
the brake holds the keys of the one instance it follows, by key id, and follows only
commands whose MAC checks out (docs/security.md has the threat model and the rules for
sessions and sequence numbers that build on this).

Wire format: `BrakeCommand.auth = CommandAuth(key_id, session, mac)`, the last field of
the message, with `mac` the last field of CommandAuth, so the MAC is the payload's last
MAC_LEN bytes. It is keyed BLAKE2b with a 32-byte tag (RFC 7693's MAC mode, hashlib)
over everything before them: the whole command (instance, decision, level, sequence
number, stamps) and the key id and session. Keyed BLAKE2b rather than HMAC-SHA256:
the same strength for this use, and about 1.4 us per command here against 4-11 us for
`hmac.digest` (OpenSSL 3 sets up a MAC context on every call): the check runs on the
brake's command path.

Key file (TOML, mode 0600, made by `aeb keygen`):

    key_id = "primary-3f9c2a1b"
    instance = "primary"
    secret = "<64 hex digits>"
    insecure_example = false     # true: published with the source, for the demo/simulator

A published example key (the flag, or one of the secrets shipped in deploy/keys/, however
its file is labelled) is known to everyone: the brake refuses it on a real actuator
unless `brake.allow_example_key` says otherwise (services/brake/main.py). Any other key
file must be readable by its owner only: a file with group or other permission bits is
refused (`KeyFileError` naming the file and its mode).
"""

import hashlib
import hmac
import os
import secrets
import stat
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import msgspec

from aeb_radar_camera.common.messages import BrakeCommand, CommandAuth, encode

MAC_LEN = 32
SECRET_LEN = 32   # BLAKE2b takes keys of up to 64 bytes
_ZERO_MAC = bytes(MAC_LEN)
# SHA-256 of the secrets published in deploy/keys/ (primary, candidate, paper): a copy of
# one of them is an example key even when its file no longer says so
PUBLISHED_SECRETS = frozenset({
    "fd180419baea56f298d331c24624e04646adb1b9f2b47341590523bfafec48b7",
    "4bb9beca03c29288760ce83c44c7de25b4453364025ef699811551df6f9a6a6f",
    "af4ce6d7f0419ad6784084225111691df353d9c34d36ee127a8ea89bbc825066",
})
# a key file's permission bits that are refused: any access by group or others
SECRET_MODE_MASK = 0o077


class KeyFileError(ValueError):
    """A key file that is missing, unreadable, malformed, or for another instance."""


@dataclass(frozen=True)
class CommandKey:
    key_id: str
    instance: str
    secret: bytes
    insecure_example: bool = False
    path: str = ""

    @property
    def published(self) -> bool:
        """An example key: labelled so, or one of the secrets shipped with the source."""
        return (self.insecure_example
                or hashlib.sha256(self.secret).hexdigest() in PUBLISHED_SECRETS)

    def __repr__(self) -> str:   # never print a secret
        return (f"CommandKey(key_id={self.key_id!r}, instance={self.instance!r}, "
                f"insecure_example={self.insecure_example}, path={self.path!r})")


class _KeyFile(msgspec.Struct, forbid_unknown_fields=True):
    key_id: str
    instance: str
    secret: str
    insecure_example: bool = False


def new_key(instance: str, key_id: str | None = None) -> CommandKey:
    """A fresh random key for `instance` (key id: the instance and 8 random hex digits)."""
    return CommandKey(key_id or f"{instance}-{secrets.token_hex(4)}", instance,
                      secrets.token_bytes(SECRET_LEN))


def key_file_text(key: CommandKey) -> str:
    head = ("# INSECURE EXAMPLE KEY: published with the source code, for the demo and the\n"
            "# simulator only. Never use it on a vehicle: make your own with `aeb keygen`.\n"
            if key.insecure_example else
            "# BrakeCommand key of one fusion instance (docs/security.md). Keep it secret:\n"
            "# readable by the fusion and brake services only (mode 0600).\n")
    return (f'{head}key_id = "{key.key_id}"\ninstance = "{key.instance}"\n'
            f'secret = "{key.secret.hex()}"\n'
            f"insecure_example = {'true' if key.insecure_example else 'false'}\n")


def write_key(path: Path, key: CommandKey, overwrite: bool = False) -> None:
    """Write `key` to `path` readable by its owner only. Raises FileExistsError unless
    `overwrite`, OSError when the file cannot be written."""
    flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
    fd = os.open(path, flags, 0o600)
    # before the secret is in it: an existing file being overwritten keeps its old mode
    os.fchmod(fd, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(key_file_text(key))


def load_key(path: str | Path) -> CommandKey:
    """Read a key file. Raises KeyFileError naming the file and what is wrong (among it:
    a key that is not an example key in a file with group or other permission bits)."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
        raw = tomllib.loads(p.read_text())
        f = msgspec.convert(raw, _KeyFile)
    except OSError as exc:
        raise KeyFileError(f"{p}: cannot read command key: {exc.strerror}") from exc
    except (tomllib.TOMLDecodeError, msgspec.ValidationError) as exc:
        raise KeyFileError(f"{p}: not a command key file: {exc}") from exc
    try:
        secret = bytes.fromhex(f.secret)
    except ValueError:
        raise KeyFileError(f"{p}: secret must be hex digits") from None
    if not 16 <= len(secret) <= 64:
        raise KeyFileError(f"{p}: secret has {len(secret)} bytes, 16 to 64 needed")
    if not f.key_id or not f.instance:
        raise KeyFileError(f"{p}: key_id and instance must not be empty")
    key = CommandKey(f.key_id, f.instance, secret, f.insecure_example, str(p))
    # an example key is public whatever its mode (and git checks it out 0644)
    if mode & SECRET_MODE_MASK and not key.published:
        raise KeyFileError(f"{p}: mode {stat.S_IMODE(mode):04o} lets group or others access "
                           f"a secret command key; make it readable by its owner only: "
                           f"chmod 600 {p}")
    return key


def load_signing_key(path: str | Path, instance: str) -> CommandKey:
    """The key fusion instance `instance` signs its commands with. Raises KeyFileError (a
    bad file, another instance's key)."""
    key = load_key(path)
    if key.instance != instance:
        raise KeyFileError(f"{path}: key of instance {key.instance!r}, this is {instance!r}")
    return key


def load_keyring(paths: Iterable[str], instance: str) -> dict[str, CommandKey]:
    """The keys the brake accepts, by key id: every file must hold a key of `instance`.
    Raises KeyFileError (no file, a bad file, another instance's key, a repeated id)."""
    keys: dict[str, CommandKey] = {}
    for path in paths:
        key = load_key(path)
        if key.instance != instance:
            raise KeyFileError(f"{path}: key of instance {key.instance!r}, the brake follows "
                               f"{instance!r}")
        if key.key_id in keys:
            raise KeyFileError(f"{path}: key id {key.key_id!r} given twice")
        keys[key.key_id] = key
    if not keys:
        raise KeyFileError("brake.command_keys is empty: the brake follows authenticated "
                           "commands only; make a key with `aeb keygen` and give its file "
                           "to the fusion instance (fusion.command_key) and the brake")
    return keys


class CommandSigner:
    """Signs the commands of one fusion process. `session` (random by default) tells the
    brake that a new process started: it is new at every start, never reused."""

    def __init__(self, key: CommandKey, session: int | None = None) -> None:
        self.key = key
        self.session = secrets.randbits(63) if session is None else session
        self._blank = CommandAuth(key.key_id, self.session, _ZERO_MAC)

    def sign(self, cmd: BrakeCommand) -> bytes:
        """The command's payload with its MAC."""
        body = encode(msgspec.structs.replace(cmd, auth=self._blank))[:-MAC_LEN]
        return body + mac(self.key.secret, body)


def mac(secret: bytes, body: bytes) -> bytes:
    """The MAC of `body` under `secret` (keyed BLAKE2b, 32 bytes)."""
    return hashlib.blake2b(body, key=secret, digest_size=MAC_LEN).digest()


def mac_problem(payload: bytes, cmd: BrakeCommand,
                keys: Mapping[str, CommandKey]) -> str | None:
    """None when `cmd` (decoded from `payload`) carries a valid MAC of one of `keys`,
    else the rejection reason: `unauthenticated`, `unknown_key` or `bad_mac`."""
    auth = cmd.auth
    if auth is None:
        return "unauthenticated"
    key = keys.get(auth.key_id)
    if key is None:
        return "unknown_key"
    # the decoded MAC must be the trailing bytes the MAC was computed in front of
    if len(auth.mac) != MAC_LEN or payload[-MAC_LEN:] != auth.mac:
        return "bad_mac"
    expected = mac(key.secret, payload[:-MAC_LEN])
    return None if hmac.compare_digest(expected, auth.mac) else "bad_mac"
