import functools

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from behaviors.domain import IvPDomain, parse_domain_line
from behaviors.ivp_function import IvPFunction, couple
from behaviors.solver import missing_decisions, solve
from behaviors.zaic import PeakComponent, zaic_heq, zaic_leq, zaic_peak


def test_domain_lines():
    v = parse_domain_line("speed:0:4:41")
    assert v.delta == pytest.approx(0.1) and v.values[-1] == pytest.approx(4.0)
    d = parse_domain_line("speed,0,4,delta=0.3")
    assert d.npts == 14 and d.delta == pytest.approx(4 / 13)
    assert parse_domain_line("depth:0:100:101:optional").optional
    for bad in ("speed:0:4", "speed:4:0:10", "speed:1:1:5", "speed:0:4:x", "depth:0:1:2:maybe"):
        with pytest.raises(ValueError):
            parse_domain_line(bad)


def test_peak_shape_matches_spec_numbers(domain):
    course = domain.var("course")
    u = zaic_peak(course, [PeakComponent(0, 30, 180, 5, 0, 20)], value_wrap=True)
    assert u[0] == 20 and u[30] == pytest.approx(15) and u[330] == pytest.approx(15)
    assert u[180] == pytest.approx(2.5)
    c0 = zaic_peak(course, [PeakComponent(90, 0, 180, 50, 0, 100)], value_wrap=True)
    assert c0[90] == 100 and c0[270] == 0 and c0[0] == pytest.approx(50)


def test_peak_summit_insist_between_grid_points():
    var = parse_domain_line("speed:0:4:5")
    u = zaic_peak(var, [PeakComponent(1.4, 0, 0.2, 0, 0, 25)])
    assert u.tolist() == [0, 25, 0, 0, 0]


def test_peak_sum_and_max_modes(domain):
    spd = domain.var("speed")
    comps = [PeakComponent(1, 0, 1, 0, 0, 50), PeakComponent(1.5, 0, 1, 0, 0, 50)]
    assert zaic_peak(spd, comps, max_mode=False)[12] == pytest.approx(40 + 35)
    assert zaic_peak(spd, comps)[12] == pytest.approx(40)
    with pytest.raises(ValueError):
        zaic_peak(spd, [PeakComponent(1, 0, 1, 0, 50, 50)])


def test_leq_and_heq(domain):
    spd = domain.var("speed")
    leq = zaic_leq(spd, 2.0, 1.0)
    assert leq[20] == 100 and leq[0] == 100 and leq[25] == pytest.approx(50) and leq[35] == 0
    heq = zaic_heq(spd, 2.0, 1.0)
    assert heq[40] == 100 and heq[15] == pytest.approx(50) and heq[5] == 0


def test_couple_spans_0_100(domain):
    crs = IvPFunction(("course",), zaic_peak(domain.var("course"), [PeakComponent(45, 0, 180)], value_wrap=True))
    spd = IvPFunction(("speed",), zaic_peak(domain.var("speed"), [PeakComponent(2, 1, 1.6, 20)]))
    f = couple(crs, spd, 70, 30, pwt=50)
    assert f.values.shape == (360, 41) and f.values.max() == pytest.approx(100) and f.values.min() == 0
    assert np.unravel_index(np.argmax(f.values), f.values.shape) == (45, 20)
    assert f.pwt == 50


def test_missing_decision_and_ignored_zero_pwt(domain):
    spd = IvPFunction(("speed",), zaic_peak(domain.var("speed"), [PeakComponent(1, 0, 1)]))
    decision = solve(domain, [spd, IvPFunction(("course",), np.ones(360), pwt=0)])
    assert decision == {"speed": 1.0}
    assert missing_decisions(domain, decision) == ["course"]


arrays = st.integers(1, 4).flatmap(lambda n: st.lists(
    st.tuples(st.sampled_from(["course", "speed", "both", "coupled"]), st.floats(0, 200),
              st.integers(0, 2**32 - 1)), min_size=n, max_size=n))


@settings(max_examples=40, deadline=None)
@given(arrays)
def test_solver_maximises_weighted_sum(specs):
    dom = IvPDomain(vars=[parse_domain_line("course:0:359:36"), parse_domain_line("speed:0:4:9")])
    fns, total = [], np.zeros((36, 9))
    for which, pwt, seed in specs:
        rng = np.random.default_rng(seed)
        if which == "course":
            f = IvPFunction(("course",), rng.uniform(0, 300, 36), pwt)
            full = np.broadcast_to(f.values[:, None], (36, 9))
        elif which == "speed":
            f = IvPFunction(("speed",), rng.uniform(0, 100, 9), pwt)
            full = np.broadcast_to(f.values[None, :], (36, 9))
        elif which == "coupled":
            f = couple(IvPFunction(("course",), rng.uniform(0, 300, 36)), IvPFunction(("speed",), rng.uniform(0, 9, 9)),
                       rng.uniform(0, 100), rng.uniform(0, 100), pwt)
            full = f.values
        else:
            f = IvPFunction(("speed", "course"), rng.uniform(0, 100, (9, 36)), pwt)
            full = f.values.T
        span = full.max() - full.min()
        scaled = (full - full.min()) * 100 / span if span > 100 else full
        total += scaled * pwt
        fns.append(f)
    decision = solve(dom, fns)
    if not decision:
        assert all(f.pwt <= 0 for f in fns)
        return
    i = dom.var("course").index_of(decision["course"]) if "course" in decision else None
    j = dom.var("speed").index_of(decision["speed"]) if "speed" in decision else None
    if i is not None and j is not None:
        assert total[i, j] == pytest.approx(total.max(), rel=1e-9, abs=1e-9)
    else:
        assert (i is None) != (j is None)
        axis_best = total[i, :] if j is None else total[:, j]
        assert axis_best.max() == pytest.approx(total.max(), rel=1e-9, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2**32 - 1), st.sampled_from([1.0, 30.0, 100.0, 250.0])), min_size=1, max_size=4))
def test_separable_functions_decide_as_their_full_grids(specs):
    """Functions kept as one-variable parts (couple's) are solved on the parts; the decision is the one
    the same utilities on the full product grid give (integer utilities: no rounding to tell them apart)."""
    dom = IvPDomain(vars=[parse_domain_line("course:0:359:36"), parse_domain_line("speed:0:4:9")])
    separable, dense = [], []
    for seed, pwt in specs:
        rng = np.random.default_rng(seed)
        f = IvPFunction(("course", "speed"), pwt=pwt,
                        parts=(rng.integers(0, 60, 36).astype(float), rng.integers(0, 40, 9).astype(float)))
        assert f.values.shape == (36, 9) and f.values[3, 4] == f.parts[0][3] + f.parts[1][4]
        separable.append(f)
        dense.append(IvPFunction(("course", "speed"), f.values.copy(), pwt))
    assert solve(dom, separable) == solve(dom, dense)


utilities = st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=12).map(np.array)


@settings(max_examples=80, deadline=None)
@given(utilities, utilities, st.floats(0, 100), st.floats(1, 300),
       st.sampled_from([None, np.nan, np.inf, -np.inf]), st.integers(0, 11))
def test_coupled_bounds_are_the_parts_ranges(course, speed, ratio, pwt, special, at):
    """couple's (min, max) per part, derived without scanning, are exactly what np.min/np.max measure
    (NaN and infinities included), and the solver decides the same with them as with measured ranges."""
    if special is not None:
        course = course.copy()
        course[at % len(course)] = special
    dom = IvPDomain(vars=[parse_domain_line(f"course:0:{len(course) - 1}:{len(course)}"),
                          parse_domain_line(f"speed:0:{len(speed) - 1}:{len(speed)}")])
    with np.errstate(invalid="ignore", over="ignore"):     # NaN and infinities are the point here
        f = couple(IvPFunction(("course",), course), IvPFunction(("speed",), speed), ratio, 100 - ratio, pwt)
    measured = tuple((float(np.min(p)), float(np.max(p))) for p in f.parts)
    assert np.array_equal(f.bounds, measured, equal_nan=True)
    assert f.has_nan() == bool(np.isnan(f.values).any())
    if not f.has_nan():
        assert solve(dom, [f]) == solve(dom, [IvPFunction(f.vars, pwt=f.pwt, parts=f.parts)])


# Summits on the domain and a base: no single peak is flat, so none has a summit insisted on its own.
peaks = st.builds(PeakComponent, st.floats(0, 359), st.floats(0, 60), st.floats(1, 200), st.floats(0, 30),
                  st.sampled_from([0.0, 10.0]), st.sampled_from([50.0, 100.0]))


@settings(max_examples=80, deadline=None)
@given(st.lists(peaks, min_size=1, max_size=4), st.booleans(), st.booleans())
def test_combined_peak_is_its_components_combined(components, value_wrap, max_mode):
    """The components' distances are computed together; the result is exactly the components'
    single peaks combined by max or sum (summit insist aside: a flat result gets a summit)."""
    course = parse_domain_line("course:0:359:360")
    singles = [zaic_peak(course, [c], value_wrap=value_wrap) for c in components]
    combined = zaic_peak(course, components, value_wrap=value_wrap, max_mode=max_mode)
    expected = functools.reduce(np.maximum if max_mode else np.add, singles)
    if expected.min() == expected.max() and any(c.minutil == expected[0] for c in components):
        first = next(c for c in components if c.minutil == expected[0])
        assert combined.max() == first.maxutil and combined[course.index_of(first.summit)] == first.maxutil
    else:
        assert np.array_equal(combined, expected)
