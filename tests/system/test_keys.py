"""Command keys: `aeb keygen`, the example keys shipped in deploy/, `aeb init` replacing
them, and the key files the services refuse."""

import stat
from pathlib import Path

import pytest

from aeb_radar_camera.common.command_auth import (
    CommandKey,
    KeyFileError,
    load_key,
    load_keyring,
    new_key,
    write_key,
)
from aeb_radar_camera.common.resources import EXAMPLE_KEYS
from aeb_radar_camera.tools import init, keygen


def test_keygen_writes_a_fresh_private_key_and_never_overwrites_silently(tmp_path: Path):
    out = tmp_path / "keys" / "primary.key"
    assert keygen.main(["--instance", "primary", "--out", str(out)]) == 0
    key = load_key(out)
    assert key.instance == "primary" and not key.insecure_example and len(key.secret) == 32
    assert stat.S_IMODE(out.stat().st_mode) == 0o600
    assert keygen.main(["--instance", "primary", "--out", str(out)]) == 2
    assert load_key(out).secret == key.secret
    assert keygen.main(["--instance", "primary", "--out", str(out), "--force"]) == 0
    assert load_key(out).secret != key.secret
    assert keygen.main(["--instance", "a/b", "--out", str(tmp_path / "x.key")]) == 2


def test_the_shipped_keys_are_labelled_insecure_examples():
    keys = sorted(EXAMPLE_KEYS.glob("*.key"))
    assert {k.stem for k in keys} >= {"primary", "candidate"}
    for path in keys:
        key = load_key(path)
        assert key.insecure_example and key.instance == path.stem
        assert "INSECURE EXAMPLE KEY" in path.read_text()


def test_init_replaces_every_example_key_in_its_copy(tmp_path: Path):
    assert init.main([str(tmp_path / "vehicle")]) == 0
    for path in sorted((tmp_path / "vehicle" / "keys").glob("*.key")):
        key, shipped = load_key(path), load_key(EXAMPLE_KEYS / path.name)
        assert not key.insecure_example and key.instance == shipped.instance
        assert key.secret != shipped.secret
        assert stat.S_IMODE(path.stat().st_mode) == 0o600


@pytest.mark.parametrize("text, error", [
    ("", "not a command key file"),
    ('key_id = "k"\ninstance = "primary"\nsecret = "zz"\n', "hex"),
    ('key_id = "k"\ninstance = "primary"\nsecret = "00"\n', "16 to 64"),
    ('key_id = "k"\ninstance = "primary"\nsecret = "' + "00" * 32 + '"\nextra = 1\n',
     "not a command key file"),
])
def test_a_bad_key_file_is_named_with_what_is_wrong(tmp_path: Path, text: str, error: str):
    path = tmp_path / "bad.key"
    path.write_text(text)
    with pytest.raises(KeyFileError, match=error):
        load_key(path)


def test_the_brake_accepts_only_keys_of_its_instance(tmp_path: Path):
    with pytest.raises(KeyFileError, match="instance 'candidate'"):
        load_keyring([str(EXAMPLE_KEYS / "candidate.key")], "primary")
    with pytest.raises(KeyFileError, match="given twice"):
        load_keyring([str(EXAMPLE_KEYS / "primary.key")] * 2, "primary")
    with pytest.raises(KeyFileError, match="cannot read"):
        load_keyring([str(tmp_path / "missing.key")], "primary")
    assert list(load_keyring([str(EXAMPLE_KEYS / "primary.key")], "primary")) == [
        "primary-insecure-example"]


def test_a_copy_of_a_published_secret_is_an_example_key_whatever_its_file_says(
        tmp_path: Path):
    shipped = load_key(EXAMPLE_KEYS / "primary.key")
    relabelled = CommandKey("mine", "primary", shipped.secret)    # insecure_example false
    write_key(tmp_path / "mine.key", relabelled)
    key = load_key(tmp_path / "mine.key")
    assert not key.insecure_example and key.published
    assert not new_key("primary").published


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o644, 0o666, 0o700])
def test_a_secret_key_file_with_group_or_other_bits_is_refused(tmp_path: Path, mode: int):
    path = tmp_path / "k.key"
    write_key(path, new_key("primary"))
    path.chmod(mode)
    if mode & 0o077:
        with pytest.raises(KeyFileError, match=f"k.key: mode {mode:04o} .*chmod 600"):
            load_key(path)
    else:
        load_key(path)


def test_the_example_keys_load_as_checked_out_and_writing_a_key_makes_it_private(
        tmp_path: Path):
    example = tmp_path / "example.key"
    example.write_text((EXAMPLE_KEYS / "primary.key").read_text())
    example.chmod(0o644)                                          # as git checks it out
    assert load_key(example).published                            # public anyway
    path = tmp_path / "k.key"
    path.write_text("old")
    path.chmod(0o666)
    write_key(path, new_key("primary"), overwrite=True)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
