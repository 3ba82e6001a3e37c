"""Parameter transforms: the prior box maps to [-1, 1], round trips, physical limits."""

import numpy as np
import pytest

from vibid.errors import VibidError
from vibid.identify.fit.space import ParameterSpace, make_transform


def test_prior_box_maps_to_unit_box_and_back():
    space = ParameterSpace.from_bounds(
        ("D", "nu", "beta"), {"D": (1.0, 100.0), "nu": (-0.5, 0.4), "beta": (1e-4, 0.1)}
    )
    lo = space.to_u([1.0, -0.5, 1e-4])
    hi = space.to_u([100.0, 0.4, 0.1])
    np.testing.assert_allclose(lo, -1.0, atol=1e-12)
    np.testing.assert_allclose(hi, 1.0, atol=1e-12)
    theta = np.array([17.97, 0.286, 0.003])
    np.testing.assert_allclose(space.theta(space.to_u(theta)), theta, rtol=1e-13)
    # log D: the middle of the box is the geometric mean
    assert float(space.theta(np.zeros(3))[0]) == pytest.approx(10.0)


def test_nu_stays_physical_for_any_u():
    t = make_transform("nu", 0.0, 0.5)
    u = np.array([-1e3, -50.0, 0.0, 50.0, 1e3])
    nu = np.asarray(t.from_u(u))
    assert np.all(nu >= -1.0) and np.all(nu <= 0.5)
    assert float(t.from_u(1.0)) == pytest.approx(0.5 - 1.5e-3)  # the edge margin


def test_dtheta_du_matches_finite_difference():
    space = ParameterSpace.from_bounds(
        ("D11", "D12", "nu"), {"D11": (1.0, 50.0), "D12": (-2.0, 5.0), "nu": (0.0, 0.5)}
    )
    u = np.array([0.3, -0.2, 0.1])
    h = 1e-6
    fd = [
        (space.theta(u + h * e)[i] - space.theta(u - h * e)[i]) / (2 * h)
        for i, e in enumerate(np.eye(3))
    ]
    np.testing.assert_allclose(space.dtheta_du(u), fd, rtol=1e-7)


def test_unknown_names_get_a_sensible_transform():
    assert make_transform("k_new", 1e-3, 10.0).kind == "log"
    assert make_transform("offset_new", -1.0, 1.0).kind == "linear"


@pytest.mark.parametrize("name,lo,hi", [("D", -1.0, -0.5), ("nu", 0.6, 0.9), ("D", 2.0, 1.0)])
def test_impossible_bounds_are_refused(name, lo, hi):
    with pytest.raises(VibidError):
        make_transform(name, lo, hi)


def test_out_of_bounds_names():
    space = ParameterSpace.from_bounds(
        ("D", "nu", "beta"), {"D": (30.0, 100.0), "nu": (0.0, 0.5), "beta": (1e-4, 0.1)}
    )
    assert space.out_of_bounds([17.97, 0.286, 0.003]) == ["D"]


def test_a_log_box_keeps_its_positive_lower_bound_over_many_decades():
    """The clamp's catalogue box, 1e2 to 1e9 N/rad, maps to [-1, 1] whole: a stiff clamp of
    1.6e4 N/rad lies inside it (u = -0.37), not below a box cut at a thousandth of its top
    (1e6, where it was u = -2.2); only a bound at 0 is moved in (mass >= 0)."""
    t = make_transform("k_theta_N_per_rad", 1e2, 1e9)
    assert float(t.to_u(1e2)) == pytest.approx(-1.0) and float(t.to_u(1e9)) == pytest.approx(1.0)
    assert float(t.to_u(1.6e4)) == pytest.approx(-0.3703, abs=1e-4)
    space = ParameterSpace.from_bounds(("k_theta_N_per_rad",), {"k_theta_N_per_rad": (1e2, 1e9)})
    assert space.out_of_bounds([1.6e4]) == []
    m = make_transform("mass_kg", 0.0, 5e-3)
    assert float(m.from_u(-1.0)) == pytest.approx(5e-6)  # a bound at 0: moved to 1e-3 of the top
