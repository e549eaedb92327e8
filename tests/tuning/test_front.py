"""The front is the set of non-dominated points; 'clearly dominated' has its margin at the boundary."""

from hypothesis import given
from hypothesis import strategies as st

from etobs.tuning.front import dominates, pareto

points = st.lists(st.tuples(st.integers(0, 6), st.integers(0, 6)), max_size=25)


@given(points)
def test_the_front_is_non_dominated_and_covers_every_other_point(pts):
    front = pareto(pts)
    assert all(not dominates(pts[j], pts[i]) for i in front for j in range(len(pts)))
    for k, p in enumerate(pts):
        if k not in front:  # dominated by, or equal to, a front point
            assert any(dominates(pts[i], p) or tuple(pts[i]) == tuple(p) for i in front)
    assert len({tuple(pts[i]) for i in front}) == len(front)  # equal points once


def test_which_points_are_on_a_front():
    assert pareto([(3, 1), (1, 3), (2, 2), (3, 3), (1, 3), (2, 3)]) == [0, 1, 2]
    assert pareto([]) == []


def test_domination_needs_one_strictly_better_objective():
    assert dominates((1, 2), (1, 3)) and not dominates((1, 3), (1, 3))
    assert not dominates((1, 4), (2, 3))
