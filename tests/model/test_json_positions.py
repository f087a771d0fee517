"""The positions json_position gives, checked against the decoder itself on random documents:
the value decoded from the position of every path is the value json.loads puts there."""

import json

import numpy as np
import pytest

from bcad.model.source import json_position

KEYS = ["a", "b", "é", 'q"uote', "back\\slash", "", "tab\t", "1"]


def random_value(rng: np.random.Generator, depth: int):
    kind = rng.integers(0, 7 if depth < 4 else 4)
    if kind == 0:
        return float(rng.normal() * 10.0 ** rng.integers(-5, 6))
    if kind == 1:
        return int(rng.integers(-1000, 1000))
    if kind == 2:
        return str(rng.choice(KEYS)) * int(rng.integers(0, 3))
    if kind == 3:
        return [None, True, False][int(rng.integers(0, 3))]
    if kind == 4:
        return [random_value(rng, depth + 1) for _ in range(rng.integers(0, 4))]
    # an object, its keys possibly repeated (json.loads keeps the last)
    return Pairs((str(rng.choice(KEYS)), random_value(rng, depth + 1)) for _ in range(rng.integers(0, 5)))


class Pairs(list):
    """An object's members in writing order (a key may come twice)."""


def written(value, rng: np.random.Generator) -> str:
    """JSON text of ``value`` (objects as lists of pairs), with random whitespace between tokens."""
    space = lambda: "".join(rng.choice([" ", "\n", "\t", "\r\n", ""], size=rng.integers(0, 3)))  # noqa: E731
    if isinstance(value, Pairs):
        pairs = [f"{space()}{json.dumps(k)}{space()}:{space()}{written(v, rng)}{space()}" for k, v in value]
        return "{" + ",".join(pairs) + space() + "}"
    if isinstance(value, list):
        return "[" + ",".join(space() + written(v, rng) + space() for v in value) + space() + "]"
    return json.dumps(value)


def paths(data, prefix=()):
    yield prefix
    if isinstance(data, dict):
        for key, value in data.items():
            yield from paths(value, (*prefix, key))
    elif isinstance(data, list):
        for index, value in enumerate(data):
            yield from paths(value, (*prefix, index))


def index_of(text: str, line: int, column: int) -> int:
    starts = [0] + [k + 1 for k, c in enumerate(text) if c == "\n"]
    return starts[line - 1] + column - 1


@pytest.mark.parametrize("seed", range(40))
def test_every_value_decodes_from_its_position(seed):
    rng = np.random.default_rng(seed)
    text = " \n" + written(Pairs((str(rng.choice(KEYS)), random_value(rng, 1)) for _ in range(4)), rng) + "\n"
    data = json.loads(text)
    decoder = json.JSONDecoder()
    checked = 0
    for loc in paths(data):
        found = json_position(text, loc)
        assert found is not None, loc
        value = data
        for step in loc:
            value = value[step]
        assert decoder.raw_decode(text, index_of(text, *found))[0] == value, loc
        checked += 1
    assert checked >= 2
    assert json_position(text, ("no such key",) * 2) is None


def test_a_key_written_twice_is_found_where_json_takes_it():
    text = '{"a": 1,\n "a": [10, 20]}'
    assert json.loads(text)["a"] == [10, 20]
    assert json_position(text, ("a",)) == (2, 7)
    assert json_position(text, ("a", 1)) == (2, 12)
    assert json_position(text, ("a", 2)) is None
    assert json_position(text, ("a", 0, "b")) is None  # a number has no keys
