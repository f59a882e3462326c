"""`aeb schemas`: the JSON Schema of every message on the bus, named as in the samples'
encodings, and describing each type field by field."""

import json

import msgspec
import pytest

from aeb_radar_camera.common.keys import REGISTRY
from aeb_radar_camera.common.messages.schema import schema_name
from aeb_radar_camera.tools.schemas import main
from tests.messages_support import example, message_types


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("schemas")
    assert main(["--out", str(out)]) == 0
    return out


def test_one_file_per_message_type_and_an_index_of_keys(exported):
    names = {p.stem for p in exported.glob("aeb.*.json")}
    assert names == {schema_name(t) for t in message_types()}
    keys = json.loads((exported / "keys.json").read_text())["keys"]
    for spec in REGISTRY.values():
        if spec.msg_type is not None:
            assert keys[spec.pattern]["schema"] == schema_name(spec.msg_type)
    assert keys["sim/world"]["simulation"] is True


@pytest.mark.parametrize("msg_type", message_types(), ids=lambda t: t.__name__)
def test_each_schema_describes_its_type_field_by_field(exported, msg_type):
    schema = json.loads((exported / f"{schema_name(msg_type)}.json").read_text())
    defs = schema["$defs"]
    top = defs[schema["$ref"].rsplit("/", 1)[1]]
    fields = msgspec.structs.fields(msg_type)
    assert set(top["properties"]) == {f.name for f in fields}
    assert set(top.get("required", [])) == {f.name for f in fields if f.required}
    # a message as JSON has exactly the schema's properties, nested ones included
    as_json = json.loads(msgspec.json.encode(example(msg_type)))
    assert set(as_json) == set(top["properties"])
    if "header" in as_json:
        assert set(as_json["header"]) == set(defs["Header"]["properties"])


def test_stdout_is_one_document(capsys):
    assert main([]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["encoding"] == "msgpack" and doc["schema_version"] >= 1
    assert "aeb.RadarTracks" in doc["schemas"]
