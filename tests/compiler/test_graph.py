"""Spanning tree, cycle counts (p = m - n + 1) and the choice of closing links."""

from __future__ import annotations

from bcad.compiler import compile_problem
from bcad.model import load_problem

from conftest import RX90_URDF


def _link(name, parent, child, extra=""):
    return f"  - {{name: {name}, parent: {parent}, child: {child}{extra}}}\n"


def _compile(write_problem, frames, links, tail=""):
    text = "name: g\nframes: [" + ", ".join(frames) + "]\nlinks:\n" + "".join(links) + tail
    return compile_problem(load_problem(write_problem(text)))


def _closing_names(compiled):
    return [compiled.graph.links[i].name for i in compiled.graph.closing_links]


def test_a_tree_has_no_cycle(write_problem):
    compiled = _compile(write_problem, "abcd", [_link("ab", "a", "b"), _link("bc", "b", "c"), _link("bd", "b", "d")])
    assert compiled.stats.cycles == 0
    assert compiled.graph.cycles == []


def test_one_cycle_is_closed_by_the_link_marked_close(write_problem):
    links = [_link("ab", "a", "b"), _link("bc", "b", "c"), _link("ca", "c", "a", ", close: true")]
    compiled = _compile(write_problem, "abc", links)
    assert compiled.stats.cycles == 1
    assert _closing_names(compiled) == ["ca"]
    # The cycle's path runs from the closing link's parent (c) to its child (a).
    path = [(compiled.graph.links[i].name, forward) for i, forward in compiled.graph.cycles[0].path]
    assert path == [("bc", False), ("ab", False)]


def test_without_a_mark_the_last_declared_link_of_a_cycle_closes_it(write_problem):
    links = [_link("ab", "a", "b"), _link("bc", "b", "c"), _link("ac", "a", "c")]
    compiled = _compile(write_problem, "abc", links)
    assert _closing_names(compiled) == ["ac"]


def test_two_independent_cycles(write_problem):
    links = [
        _link("ab", "a", "b"),
        _link("bc", "b", "c"),
        _link("ca", "c", "a", ", close: true"),
        _link("cd", "c", "d"),
        _link("de", "d", "e"),
        _link("ec", "e", "c", ", close: true"),
    ]
    compiled = _compile(write_problem, "abcde", links)
    assert compiled.stats.cycles == len(links) - 5 + 1 == 2
    assert _closing_names(compiled) == ["ca", "ec"]
    first, second = compiled.graph.cycles
    assert {compiled.graph.links[i].name for i, _ in first.path} == {"ab", "bc"}
    assert {compiled.graph.links[i].name for i, _ in second.path} == {"cd", "de"}


def test_two_parallel_links_make_a_cycle(write_problem):
    compiled = _compile(write_problem, "ab", [_link("one", "a", "b"), _link("two", "a", "b")])
    assert compiled.stats.cycles == 1
    assert _closing_names(compiled) == ["two"]


def test_a_link_parallel_to_a_robot_closes_one_cycle_and_the_robot_stays_in_the_tree(write_problem):
    text = f"""
    name: parallel
    frames: [world, tool]
    robots:
      - name: arm
        urdf: {RX90_URDF}
        parent: world
    links:
      - {{name: mount, parent: arm/link_6, child: tool}}
      - {{name: fixture, parent: world, child: tool}}
    """
    compiled = compile_problem(load_problem(write_problem(text)))
    # 2 + 7 URDF link frames; 2 links + base + 6 joints.
    assert compiled.stats.frames == 9
    assert compiled.stats.links == 9
    assert compiled.stats.cycles == 1
    assert _closing_names(compiled) == ["fixture"]
    assert len(compiled.graph.cycles[0].path) == 8  # base, six joints, mount


def test_relations_close_cycles_before_plain_links(write_problem):
    text = """
    name: rel
    frames: [a, b]
    links:
      - {name: ab, parent: a, child: b, status: LFFFFF, distributions: {tx: 'normal(0, 1)'}}
    entities:
      - {name: fa, type: face, frame: a, size: [2, 2]}
      - {name: pb, type: point, frame: b}
    relations:
      - name: touch
        type: point_on_face
        parent: fa
        child: pb
        status: FFLFFF
        distributions: {tz: 'normal(0, 0.1)'}
    """
    compiled = compile_problem(load_problem(write_problem(text)))
    assert _closing_names(compiled) == ["touch"]
    assert compiled.stats.inequality_constraints == 4
    assert compiled.parameters.l_names == ["ab.tx"]
    assert [p.name for p in compiled.parameters.observed] == ["touch.tz"]
