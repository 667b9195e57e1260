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
