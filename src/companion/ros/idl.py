"""cyclonedds IDL types built from rosbags' typestore, so DDS announces the types it carries.

The bytes companion sends are rosbags' CDR (:mod:`companion.ros.dds` writes them as they are);
cyclonedds still needs a type for each topic, whose name and layout it announces in discovery
(the XTypes type information that rmw_cyclonedds_cpp peers check). :func:`idl_type` builds that
type from the typestore's field definitions, so the announced layout and the bytes come from the
same source; a test checks that cyclonedds' own serialiser of these types gives rosbags' bytes.
"""

from __future__ import annotations

from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as idl
from rosbags.typesys.store import Nodetype

from companion.ros.messages import dds_type_name

#: ROS 2 primitive types -> IDL (a ROS ``char`` is an IDL ``uint8``, as rosidl maps it).
PRIMITIVES: dict[str, Any] = {
    "bool": bool, "byte": idl.byte, "char": idl.uint8,
    "int8": idl.int8, "uint8": idl.uint8, "int16": idl.int16, "uint16": idl.uint16,
    "int32": idl.int32, "uint32": idl.uint32, "int64": idl.int64, "uint64": idl.uint64,
    "float32": idl.float32, "float64": idl.float64,
}

# One class per (typestore, message type) for the life of the process: cyclonedds keeps a
# registry of the types it has seen, and a second class of the same name is a needless copy.
_TYPES: dict[tuple[int, str], tuple[Any, type[IdlStruct]]] = {}


def idl_type(typestore: Any, msgtype: str, request_header: bool = False) -> type[IdlStruct]:
    """The cyclonedds struct of ``msgtype`` (``'geometry_msgs/msg/Twist'``), named as DDS names
    it (``geometry_msgs::msg::dds_::Twist_``), with nested messages, fixed arrays, bounded and
    unbounded sequences and strings as the typestore defines them. ``request_header``: a
    service's request or reply as rmw_cyclonedds_cpp sends it, after its 16-byte header (client
    id, sequence number; :data:`companion.ros.dds_base.REQUEST_HEADER`), so that cyclonedds
    checks the samples against their real layout."""
    key = (id(typestore), msgtype, request_header)
    if key not in _TYPES:
        fields = {"request_header_guid": idl.uint64,
                  "request_header_seq": idl.int64} if request_header else {}
        fields.update({name: _field(typestore, desc)
                       for name, desc in typestore.fielddefs[msgtype][1]})
        cls = make_idl_struct(msgtype.replace("/", "__") + "__with_header" * request_header,
                              dds_type_name(msgtype), fields)
        _TYPES[key] = (typestore, cls)   # the typestore is kept so its id stays unique
    return _TYPES[key][1]


def _field(typestore: Any, desc: tuple) -> Any:
    """The IDL type of one rosbags field description ``(Nodetype, details)``."""
    kind, detail = desc
    if kind == Nodetype.BASE:
        name, bound = detail
        if name == "string":
            return idl.bounded_str[bound] if bound else str
        if name not in PRIMITIVES:
            raise ValueError(f"ROS type {name!r} has no IDL mapping here")
        return PRIMITIVES[name]
    if kind == Nodetype.NAME:
        return idl_type(typestore, detail)
    sub, size = detail
    element = _field(typestore, sub)
    if kind == Nodetype.ARRAY:
        return idl.array[element, size]
    return idl.sequence[element, size] if size else idl.sequence[element]
