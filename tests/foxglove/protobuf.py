"""Decode Foxglove-schema payloads with the schema that came with them (a protobuf
FileDescriptorSet), as Foxglove itself does: nothing here knows the schemas in advance."""

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import Message


def message_class(schema_name: str, file_descriptor_set: bytes) -> type[Message]:
    fds = descriptor_pb2.FileDescriptorSet.FromString(file_descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def decode(schema_name: str, file_descriptor_set: bytes, payload: bytes) -> Message:
    """Raises google.protobuf.message.DecodeError for a payload that does not parse."""
    return message_class(schema_name, file_descriptor_set).FromString(payload)
