"""JSON values as types: what a ``.json`` artifact (gains.json, meta.json) may hold.

A field typed :data:`JSONObject` says what it is — data that round-trips through
``json.dumps``/``json.loads`` unchanged — where ``dict[str, Any]`` would say nothing.
"""

from __future__ import annotations

from typing import TypeAlias

#: a JSON value: null, a boolean, a number, a string, an array or an object of them
JSONValue: TypeAlias = "None | bool | int | float | str | list[JSONValue] | dict[str, JSONValue]"
#: a JSON object
JSONObject: TypeAlias = "dict[str, JSONValue]"
