"""The per-step fast paths: compiled value writers (fmus._names.writer) and the master's
block moves for wired vector signals (cosim.engine.execution._runs)."""

from __future__ import annotations

import ctypes

import pytest

from cosim.engine.execution import _runs
from fmus._names import writer


def test_writer_stores_each_group_under_its_names():
    values = {"other": 7.0}
    write = writer(("q[1]", "q[2]", "q[3]"), ("p.x",))
    write(values, (1.0, 2.0, 3.0), [4.0])
    assert values == {"other": 7.0, "q[1]": 1.0, "q[2]": 2.0, "q[3]": 3.0, "p.x": 4.0}


def test_writer_quotes_any_name():
    values: dict = {}
    name = "a'b\"c\\d\n"
    writer([name])(values, [1.5])
    assert values == {name: 1.5}


def test_writer_rejects_a_sequence_of_the_wrong_length():
    with pytest.raises(ValueError):
        writer(("a", "b"))({}, (1.0,))
    with pytest.raises(ValueError):
        writer(("a", "b"))({}, (1.0, 2.0, 3.0))


@pytest.mark.parametrize("groups", [(), ((),), ((1, 2),)])
def test_writer_needs_groups_of_names(groups):
    with pytest.raises(ValueError, match="writer needs"):
        writer(*groups)


def _apply(moves, copies):
    for d, s in moves:
        d[:] = s
    for dv, di, sv, si in copies:
        dv[di] = sv[si]


def test_consecutive_numeric_links_become_one_move_with_the_same_result():
    src = (ctypes.c_double * 9)(*[float(i) for i in range(9)])
    other = (ctypes.c_double * 3)(10.0, 11.0, 12.0)
    dst = (ctypes.c_double * 12)()
    links = [(dst, i, src, i) for i in range(9)] + [(dst, 9 + i, other, i) for i in range(3)]
    moves, copies = _runs(links)
    assert [(d.nbytes, s.nbytes) for d, s in moves] == [(9 * 8, 9 * 8), (3 * 8, 3 * 8)] and copies == []
    _apply(moves, copies)
    assert list(dst) == [float(i) for i in range(9)] + [10.0, 11.0, 12.0]


def test_gaps_single_values_strings_and_mixed_types_stay_element_copies():
    src = (ctypes.c_double * 4)(1.0, 2.0, 3.0, 4.0)
    dst = (ctypes.c_double * 4)()
    i32 = (ctypes.c_int32 * 2)(5, 6)
    i64 = (ctypes.c_int64 * 2)()
    s_src = (ctypes.c_char_p * 2)(b"a", b"b")
    s_dst = (ctypes.c_char_p * 2)()
    links = [(dst, 0, src, 0), (dst, 1, src, 2),  # a gap on the source side: two single copies
             (i64, 0, i32, 0), (i64, 1, i32, 1),  # different element types convert through Python
             (s_dst, 0, s_src, 0), (s_dst, 1, s_src, 1)]  # strings are never moved as pointers
    moves, copies = _runs(links)
    assert moves == [] and len(copies) == len(links)
    _apply(moves, copies)
    assert list(dst[:2]) == [1.0, 3.0] and list(i64) == [5, 6] and list(s_dst) == [b"a", b"b"]
