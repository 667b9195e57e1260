"""Config values as text (command-line flags, sweep specs): one parser per field type.

Light on purpose (no JAX): the evaluation and the sweeps read seed lists with it too.
"""

from __future__ import annotations

from adarl.errors import UsageError

#: The most numbers a list such as `0-4` may hold (`--seeds`, `--hidden`); its ranges are counted
#: before they are expanded, so `0-100000000` costs nothing to refuse.
MAX_LIST = 1_000_000


class ListTooLong(ValueError):
    """A list of more than `most` numbers (`count`), refused before it was expanded."""

    def __init__(self, count: int, most: int):
        super().__init__(f"{count} numbers, more than {most}")
        self.count, self.most = count, most


def parse_int_list(text: str, most: int = MAX_LIST) -> tuple[int, ...]:
    """'0-4' -> (0, 1, 2, 3, 4); '0,2,5' -> (0, 2, 5); ranges and lists mix ('0-2,7').
    Raises ValueError on anything else (an empty list, a descending range, a non-number), and
    `ListTooLong` (counted, not expanded) for more than `most` numbers."""
    ranges: list[tuple[int, int]] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        lo, dash, hi = part.partition("-")
        a, b = (int(lo), int(hi)) if dash and lo else (int(part), int(part))
        if b < a:
            raise ValueError
        ranges.append((a, b))
    if not ranges:
        raise ValueError
    count = sum(b - a + 1 for a, b in ranges)
    if count > most:
        raise ListTooLong(count, most)
    return tuple(i for a, b in ranges for i in range(a, b + 1))


def split_specs(text: str) -> tuple[str, ...]:
    """Comma-separated items, where a `key=value` piece without its own `name:` prefix belongs to
    the item before it: 'nominal,fixed:a=1,b=2' -> ('nominal', 'fixed:a=1,b=2')."""
    items: list[str] = []
    for part in text.split(","):
        if not part:
            continue
        if items and "=" in part and ":" not in part and ":" in items[-1]:
            items[-1] += "," + part
        else:
            items.append(part)
    return tuple(items)


def type_text(hint) -> str:
    """A field's type as the parser names it: 'int', 'float | None', 'tuple[int, ...]'."""
    text = str(hint) if not isinstance(hint, type) else hint.__name__
    return text.replace("typing.", "").replace("Optional[", "").replace("NoneType", "None")


_EXPECTED = {  # what a field of each type allows, in the words of an error message
    "int": "an integer",
    "float": "a number",
    "bool": "true or false",
    "str": "text",
    "tuple[int,...]": "a list of integers",
    "tuple[str,...]": "a list of text items",
}


def field_value(name: str, value, type_text: str, where: str | None = None):
    """`value` of the field `name` as the config holds it: text (a flag, a sweep spec) is parsed
    by `parse_value`; anything else (a value read from YAML: config.yaml, a sweep file) must
    already have the field's type, a list standing for a tuple. Ints stand for floats and are
    kept as they are (an int written to config.yaml reads back an int). A one-line UsageError
    otherwise, naming `where` (a file) and the field if given, else the flag."""
    t = type_text.replace(" ", "")
    optional = t.endswith("|None")
    t = t.removesuffix("|None")
    if isinstance(value, str):
        try:
            return parse_value(name, value, type_text)
        except UsageError:
            if where is None:
                raise
    elif value is None and optional:
        return None
    elif t.startswith("tuple[") and isinstance(value, list | tuple):
        item = t.removeprefix("tuple[").removesuffix(",...]")
        if all(_has_type(v, item) for v in value):
            return tuple(value)
    elif _has_type(value, t):
        return value
    allowed = _EXPECTED.get(t, t) + (" or null" if optional else "")
    if where is None:
        raise UsageError(f"--{name.replace('_', '-')} expects {allowed}, got {value!r}")
    raise UsageError(f"{where} field {name!r} is {value!r}; allowed: {allowed}")


def _has_type(value, t: str) -> bool:
    if t == "bool":
        return isinstance(value, bool)
    if isinstance(value, bool):  # YAML's true is no number
        return False
    if t == "int":
        return isinstance(value, int)
    if t == "float":
        return isinstance(value, int | float)
    return t == "str" and isinstance(value, str)


def parse_value(name: str, text: str, type_text: str):
    """Convert a flag's text to the field's type (`int`, `float`, `bool`, tuples, optionals)."""
    t = type_text.replace(" ", "")
    flag = "--" + name.replace("_", "-")
    if t.endswith("|None") and text.lower() in ("none", "off", ""):
        return None
    t = t.removesuffix("|None")
    try:
        if t == "int":
            return int(text)
        if t == "float":
            return float(text)
        if t == "bool":
            lowered = text.lower()
            if lowered not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return lowered in ("true", "1", "yes")
        if t == "str":
            return text
        if t == "tuple[int,...]":
            return parse_int_list(text)
        if t == "tuple[str,...]":
            return split_specs(text)
    except ListTooLong as error:
        raise UsageError(
            f"{flag} {text!r} is {error.count:,} numbers; allowed: at most {error.most:,}"
        ) from None
    except ValueError:
        raise UsageError(f"{flag} expects {t}, got {text!r}") from None
    raise UsageError(f"{flag}: unsupported field type {t}")
