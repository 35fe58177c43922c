"""Unit tests of the scalar building blocks in ``flock_swarm.core.potentials``.

Oracles: hand-derived values, closed forms and central finite differences; never an output of
the code under test.
"""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from flock_swarm.core import potentials as pot

# Step of the central differences; truncation error O(FD_STEP^2) ~ 1e-12 relative.
FD_STEP = 1e-6
# Su, Wang, Lin 2009 (Fig. 2) interaction parameters.
SU_R, SU_D, SU_EPS = 4.0, 3.3, 0.1


def central_difference(f, x, step=FD_STEP):
    """Return ``(f(x + step) - f(x - step)) / (2 step)`` elementwise."""
    x = np.asarray(x, dtype=float)
    return (f(x + step) - f(x - step)) / (2.0 * step)


def sigma_of(dist, eps):
    """Return the textbook sigma-norm ``(sqrt(1 + eps d^2) - 1) / eps`` (Su09 Section II)."""
    return (math.sqrt(1.0 + eps * dist * dist) - 1.0) / eps


SU_R_ALPHA = sigma_of(SU_R, SU_EPS)
SU_D_ALPHA = sigma_of(SU_D, SU_EPS)


# --------------------------------------------------------------------------------------------
# sigma-norm and its gradient


@pytest.mark.parametrize('z', [np.array([3.3, 0.0]), np.array([1.98, 2.64]),
                               np.array([0.0, 0.0, 3.3]), np.array([1.1, -2.2, 2.2])])
def test_sigma_norm_hand_value(z):
    # ||z|| = 3.3 (1.98 = 0.6 * 3.3, 2.64 = 0.8 * 3.3; 1.1^2 + 2 * 2.2^2 = 10.89 = 3.3^2):
    # sqrt(1 + 0.1 * 10.89) = sqrt(2.089), so ||z||_sigma = (sqrt(2.089) - 1) / 0.1 = 4.45337...
    expected = (math.sqrt(2.089) - 1.0) / 0.1
    assert_allclose(pot.sigma_norm(z, 0.1), expected, rtol=1e-13)
    assert_allclose(expected, 4.453373, rtol=1e-6)


@pytest.mark.parametrize('eps', [0.01, 0.1, 1.0, 5.0])
@pytest.mark.parametrize('dim', [1, 2, 3])
def test_sigma_norm_matches_definition(eps, dim):
    rng = np.random.default_rng(11)
    z = rng.uniform(-10.0, 10.0, size=(50, dim))
    expected = (np.sqrt(1.0 + eps * np.sum(z * z, axis=1)) - 1.0) / eps
    # The textbook form cancels for small eps ||z||^2: its absolute error is ~ 1e-16 / eps.
    assert_allclose(pot.sigma_norm(z, eps), expected, rtol=1e-12, atol=1e-15 / eps)


@pytest.mark.parametrize('length', [1e-3, 1e-6, 1e-9])
@pytest.mark.parametrize('eps', [0.1, 2.0])
def test_sigma_norm_small_argument_limit(length, eps):
    # sqrt(1 + x) = 1 + x/2 - x^2/8 + ..., x = eps s^2:  ||z||_sigma = s^2/2 - eps s^4/8 + O(s^6).
    z = np.array([0.6, 0.8]) * length
    expected = length ** 2 / 2.0 - eps * length ** 4 / 8.0
    assert_allclose(pot.sigma_norm(z, eps), expected, rtol=1e-12)
    assert_allclose(pot.sigma_norm(z, eps), length ** 2 / 2.0, rtol=eps * length ** 2)


def test_sigma_norm_is_zero_at_origin_and_broadcasts():
    z = np.zeros((4, 5, 3))
    out = pot.sigma_norm(z, 0.1)
    assert out.shape == (4, 5)
    assert_allclose(out, 0.0, atol=0.0)


@pytest.mark.parametrize('eps', [0.1, 1.0])
@pytest.mark.parametrize('dim', [2, 3])
def test_sigma_grad_is_gradient_of_sigma_norm(eps, dim):
    rng = np.random.default_rng(5)
    z = rng.uniform(-5.0, 5.0, size=(20, dim))
    fd = np.empty_like(z)
    for k in range(dim):
        e = np.zeros(dim)
        e[k] = FD_STEP
        fd[:, k] = (pot.sigma_norm(z + e, eps) - pot.sigma_norm(z - e, eps)) / (2.0 * FD_STEP)
    assert_allclose(pot.sigma_grad(z, eps), fd, rtol=1e-7, atol=1e-9)


# --------------------------------------------------------------------------------------------
# bump rho_h and the influence map


@pytest.mark.parametrize('h', [0.2, 0.5, 0.9])
def test_bump_hand_values(h):
    # rho_h = 1 on [0, h), (1 + cos(pi (z - h)/(1 - h)))/2 on [h, 1]: at h cos 0 = 1 -> 1; at the
    # midpoint (1 + h)/2 cos(pi/2) = 0 -> 1/2; at 1 cos(pi) = -1 -> 0; 0 beyond 1 and below 0.
    z = np.array([0.0, 0.5 * h, h, 0.5 * (1.0 + h), 1.0, 1.0 + 1e-9, 1.5, 10.0, -1e-9, -0.3])
    expected = np.array([1.0, 1.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert_allclose(pot.bump(z, h), expected, rtol=0.0, atol=1e-15)


@pytest.mark.parametrize('h', [0.2, 0.9])
def test_bump_quarter_point(h):
    # At z = h + (1 - h)/4 the cosine argument is pi/4: (1 + sqrt(2)/2)/2.
    z = h + 0.25 * (1.0 - h)
    assert_allclose(pot.bump(z, h), 0.5 + math.sqrt(2.0) / 4.0, rtol=1e-14)


@pytest.mark.parametrize('h', [0.2, 0.5, 0.9])
@pytest.mark.parametrize('point', ['h', 'one'])
def test_bump_is_continuous_at_the_joints(h, point):
    x = h if point == 'h' else 1.0
    tiny = 1e-10
    left, right = pot.bump(np.array([x - tiny, x + tiny]), h)
    # |rho'| <= pi / (2 (1 - h)), so the jump over 2 tiny is below pi tiny / (1 - h).
    assert abs(left - right) <= math.pi * tiny / (1.0 - h)


@pytest.mark.parametrize('h', [0.2, 0.5, 0.9])
def test_bump_derivative_matches_finite_differences(h):
    # Away from the joints h and 1, where rho_h is only C^1 (second derivative jumps).
    z = np.linspace(0.01, 1.4, 97)
    z = z[(np.abs(z - h) > 1e-3) & (np.abs(z - 1.0) > 1e-3)]
    fd = central_difference(lambda x: pot.bump(x, h), z)
    assert_allclose(pot.bump_derivative(z, h), fd, rtol=0.0, atol=1e-7)


@pytest.mark.parametrize('h', [0.2, 0.5, 0.9])
def test_bump_is_c1_at_the_joints(h):
    # The ramp's slope is -pi/(2(1-h)) sin(pi (z-h)/(1-h)): sin 0 = sin pi = 0 at both joints,
    # matching the zero slope of the constant pieces on either side.
    tiny = 1e-9
    z = np.array([h - tiny, h, h + tiny, 1.0 - tiny, 1.0, 1.0 + tiny])
    assert_allclose(pot.bump_derivative(z, h), 0.0, atol=1e-7 / (1.0 - h) ** 2)


def test_bump_derivative_hand_value():
    # At the midpoint of the ramp the slope is -pi / (2 (1 - h)) (sin(pi/2) = 1).
    h = 0.2
    assert_allclose(pot.bump_derivative(0.6, h), -math.pi / 1.6, rtol=1e-14)


@pytest.mark.parametrize('delta', [0.2, 0.5, 0.9])
def test_influence_map_k1_is_the_bump(delta):
    z = np.linspace(-0.5, 1.5, 201)
    assert_allclose(pot.influence_map(z, delta, 1), pot.bump(z, delta), rtol=0.0, atol=1e-15)


@pytest.mark.parametrize('k', [1, 2, 3])
def test_influence_map_hand_values(k):
    # OS03 eq. (4): 2^-k (1 + cos(pi (z - delta)/(1 - delta)))^k; at the midpoint cos = 0 -> 2^-k.
    delta = 0.2
    z = np.array([0.0, delta, 0.6, 1.0, 1.2, -0.1])
    expected = np.array([1.0, 1.0, 2.0 ** -k, 0.0, 0.0, 0.0])
    assert_allclose(pot.influence_map(z, delta, k), expected, rtol=0.0, atol=1e-15)


@pytest.mark.parametrize('k', [1, 2, 3])
@pytest.mark.parametrize('delta', [0.2, 0.7])
def test_influence_map_derivative_matches_finite_differences(k, delta):
    z = np.linspace(0.01, 1.4, 97)
    z = z[(np.abs(z - delta) > 1e-3) & (np.abs(z - 1.0) > 1e-3)]
    fd = central_difference(lambda x: pot.influence_map(x, delta, k), z)
    assert_allclose(pot.influence_map_derivative(z, delta, k), fd, rtol=0.0, atol=1e-7)


# --------------------------------------------------------------------------------------------
# phi, phi_alpha, psi_alpha (Olfati-Saber 2006 as used by Su 2009)


@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0), (2.0, 7.0), (0.3, 0.4)])
def test_phi_is_zero_at_zero(a, b):
    # c = |a-b|/sqrt(4ab) gives sigma_1(c) = c/sqrt(1+c^2) = (b-a)/(a+b) for a <= b, so
    # phi(0) = ((b - a) + (a - b))/2 = 0.
    assert_allclose(pot.phi(0.0, a, b), 0.0, atol=1e-15)


@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0), (2.0, 7.0)])
def test_phi_limits(a, b):
    # sigma_1 -> +-1, so phi -> ((a+b) + (a-b))/2 = a and (-(a+b) + (a-b))/2 = -b.
    assert_allclose(pot.phi(1e7, a, b), a, rtol=1e-9)
    assert_allclose(pot.phi(-1e7, a, b), -b, rtol=1e-9)


@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0)])
def test_phi_is_increasing(a, b):
    values = pot.phi(np.linspace(-20.0, 20.0, 401), a, b)
    assert np.all(np.diff(values) > 0.0)


@pytest.mark.parametrize('h', [0.2, 0.9])
@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0)])
def test_phi_alpha_zero_at_d_and_beyond_r(h, a, b):
    z = np.array([SU_D_ALPHA, SU_R_ALPHA, SU_R_ALPHA * (1 + 1e-12), 1.5 * SU_R_ALPHA, 100.0])
    assert_allclose(pot.phi_alpha(z, SU_R_ALPHA, SU_D_ALPHA, h, a, b), 0.0, atol=1e-14)


@pytest.mark.parametrize('h', [0.2, 0.9])
def test_phi_alpha_sign(h):
    # Repulsion (negative) below d_alpha, attraction (positive) between d_alpha and r_alpha.
    below = np.linspace(0.0, SU_D_ALPHA, 50, endpoint=False)
    above = np.linspace(SU_D_ALPHA, SU_R_ALPHA, 50)[1:-1]
    assert np.all(pot.phi_alpha(below, SU_R_ALPHA, SU_D_ALPHA, h, 5.0, 5.0) < 0.0)
    assert np.all(pot.phi_alpha(above, SU_R_ALPHA, SU_D_ALPHA, h, 5.0, 5.0) > 0.0)


@pytest.mark.parametrize('h', [0.2, 0.9])
@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0)])
def test_psi_alpha_zero_at_d(h, a, b):
    assert_allclose(pot.psi_alpha(SU_D_ALPHA, SU_R_ALPHA, SU_D_ALPHA, h, a, b), 0.0,
                    atol=1e-15)


@pytest.mark.parametrize('h', [0.2, 0.9])
@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0)])
def test_psi_alpha_derivative_is_phi_alpha(h, a, b):
    z = np.linspace(0.05, SU_R_ALPHA - 0.05, 41)
    fd = central_difference(lambda x: pot.psi_alpha(x, SU_R_ALPHA, SU_D_ALPHA, h, a, b), z)
    exact = pot.phi_alpha(z, SU_R_ALPHA, SU_D_ALPHA, h, a, b)
    assert_allclose(fd, exact, rtol=0.0, atol=1e-7)


@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0), (2.0, 7.0)])
def test_psi_alpha_closed_form_on_the_plateau(a, b):
    # With h = 0.9 (Su09 Fig. 2), h r_alpha = 5.51 > d_alpha = 4.45, so on [0, h r_alpha] the bump
    # is 1 and psi_alpha(z) = int_{d_alpha}^{z} phi(s - d_alpha) ds. With x = s - d_alpha,
    # c = |a-b|/sqrt(4ab) and int sigma_1(x + c) dx = sqrt(1 + (x + c)^2):
    # psi_alpha(z) = (a+b)/2 [sqrt(1 + (z - d + c)^2) - sqrt(1 + c^2)] + (a-b)/2 (z - d).
    h = 0.9
    c = abs(a - b) / math.sqrt(4.0 * a * b)
    z = np.linspace(0.0, h * SU_R_ALPHA, 23)
    x = z - SU_D_ALPHA
    expected = 0.5 * (a + b) * (np.sqrt(1.0 + (x + c) ** 2) - math.sqrt(1.0 + c * c)) \
        + 0.5 * (a - b) * x
    assert_allclose(pot.psi_alpha(z, SU_R_ALPHA, SU_D_ALPHA, h, a, b), expected,
                    rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize('h', [0.2, 0.9])
def test_psi_alpha_constant_beyond_r(h):
    z = np.array([SU_R_ALPHA, 1.01 * SU_R_ALPHA, 2.0 * SU_R_ALPHA, 1e3])
    values = pot.psi_alpha(z, SU_R_ALPHA, SU_D_ALPHA, h, 5.0, 5.0)
    assert_allclose(values, values[0], rtol=1e-14)
    assert values[0] > 0.0


@pytest.mark.parametrize('h', [0.2, 0.9])
@pytest.mark.parametrize('a, b', [(5.0, 5.0), (1.0, 5.0)])
def test_psi_alpha_maximal_at_zero_and_nonnegative(h, a, b):
    # Su09 Fig. 1: maximum as ||q_i - q_j||_sigma -> 0, unique minimum 0 at d_alpha.
    z = np.linspace(0.0, 1.3 * SU_R_ALPHA, 131)
    values = pot.psi_alpha(z, SU_R_ALPHA, SU_D_ALPHA, h, a, b)
    assert np.argmax(values) == 0
    assert np.all(values[1:] < values[0])
    assert np.all(values >= -1e-14)


def test_psi_alpha_keeps_shape():
    z = np.full((2, 3), SU_D_ALPHA)
    assert pot.psi_alpha(z, SU_R_ALPHA, SU_D_ALPHA, 0.2, 5.0, 5.0).shape == (2, 3)


# --------------------------------------------------------------------------------------------
# Olfati-Saber 2003: penalty, sigmoid, action function


@pytest.mark.parametrize('a, b', [(1.0, 5.0), (2.0, 3.0), (0.5, 10.0)])
def test_os2003_penalty_minimum_zero_at_zero(a, b):
    z = np.linspace(-20.0, 20.0, 401)
    values = pot.os2003_penalty(z, a, b)
    assert_allclose(pot.os2003_penalty(0.0, a, b), 0.0, atol=1e-15)
    assert np.all(values >= -1e-15)
    assert np.all(values[z != 0.0] > 0.0)


@pytest.mark.parametrize('a, b', [(1.0, 5.0), (2.0, 3.0), (0.5, 10.0)])
def test_os2003_sigmoid_is_derivative_of_penalty(a, b):
    z = np.linspace(-15.0, 15.0, 121)
    fd = central_difference(lambda x: pot.os2003_penalty(x, a, b), z)
    # Round-off of the differences: |psi| <= 150 here, 150 * 1e-16 / FD_STEP ~ 2e-8.
    assert_allclose(pot.os2003_sigmoid(z, a, b), fd, rtol=0.0, atol=1e-7)


@pytest.mark.parametrize('a, b', [(1.0, 5.0), (2.0, 3.0), (0.5, 10.0)])
def test_os2003_sigmoid_properties(a, b):
    # OS03 Remark 5: sigma(0) = 0, z sigma(z) > 0 for z != 0, limits a and -b.
    z = np.concatenate((np.linspace(-30.0, -1e-3, 100), np.linspace(1e-3, 30.0, 100)))
    assert_allclose(pot.os2003_sigmoid(0.0, a, b), 0.0, atol=1e-15)
    assert np.all(z * pot.os2003_sigmoid(z, a, b) > 0.0)
    assert_allclose(pot.os2003_sigmoid(1e7, a, b), a, rtol=1e-8)
    assert_allclose(pot.os2003_sigmoid(-1e7, a, b), -b, rtol=1e-8)


@pytest.mark.parametrize('k', [1, 2])
@pytest.mark.parametrize('d_alpha, r', [(7.0, 8.4), (1.0, 2.0)])
def test_os2003_action_is_derivative_of_pair_potential(k, d_alpha, r):
    a, b, delta = 1.0, 5.0, 0.2
    dist = np.linspace(0.05, 1.2 * r, 97)
    fd = central_difference(
        lambda x: pot.os2003_pair_potential(x, d_alpha, r, a, b, delta, k), dist)
    action = pot.os2003_action(dist - d_alpha, d_alpha, r, a, b, delta, k)
    assert_allclose(action, fd, rtol=0.0, atol=1e-7)


def test_os2003_action_zero_at_d_and_beyond_r():
    d_alpha, r = 7.0, 8.4
    z = np.array([0.0, r - d_alpha, r - d_alpha + 1.0, 50.0])
    assert_allclose(pot.os2003_action(z, d_alpha, r, 1.0, 5.0, 0.2, 1), 0.0, atol=1e-15)


def test_os2003_pair_potential_hand_value():
    # On the plateau (dist/r <= delta) psi_hat = psi_alpha(dist - d). At dist = d + 1 with
    # a = 1, b = 4: c = 3/4, sqrt(1 + c^2) = 5/4, (z + c) = 7/4, sqrt(1 + 49/16) = sqrt(65)/4;
    # psi = 5/2 (sqrt(65)/4 - 5/4) + (-3/2) * 1.
    d_alpha, r = 1.0, 20.0
    expected = 2.5 * (math.sqrt(65.0) / 4.0 - 1.25) - 1.5
    value = pot.os2003_pair_potential(2.0, d_alpha, r, 1.0, 4.0, 0.2, 1)
    assert_allclose(value, expected, rtol=1e-14)


# --------------------------------------------------------------------------------------------
# Zhou 2012 potential


@pytest.mark.parametrize('c1, c2', [(0.5, 0.5), (1.0, 4.0), (2.0, 0.5)])
def test_zhou_potential_minimum(c1, c2):
    # dV/ds = 2 c1/s - 2 c2/s^3 = 0 at s^2 = c2/c1 (Zhou12 after eq. (3)).
    s_star = math.sqrt(c2 / c1)
    s = np.linspace(0.05 * s_star, 5.0 * s_star, 2001)
    values = pot.zhou_potential(s, c1, c2)
    assert_allclose(s[np.argmin(values)], s_star, rtol=5e-3)
    assert np.all(values >= pot.zhou_potential(s_star, c1, c2) - 1e-12)
    assert_allclose(pot.zhou_potential_derivative(s_star, c1, c2), 0.0, atol=1e-14)
    # V(s*) = c1 ln(c2/c1) + c1.
    assert_allclose(pot.zhou_potential(s_star, c1, c2), c1 * math.log(c2 / c1) + c1, atol=1e-14)


@pytest.mark.parametrize('c1, c2', [(0.5, 0.5), (1.0, 4.0)])
def test_zhou_potential_derivative_matches_finite_differences(c1, c2):
    s = np.linspace(0.2, 10.0, 50)
    fd = central_difference(lambda x: pot.zhou_potential(x, c1, c2), s)
    assert_allclose(pot.zhou_potential_derivative(s, c1, c2), fd, rtol=1e-7, atol=1e-8)


# --------------------------------------------------------------------------------------------
# Yu 2010 pair force


def test_yu_pair_gain_vanishes_at_paper_distance():
    # Yu10 Section 4.1: a = 1, b = 20, c_bar = 0.2, d = sqrt(c_bar ln(b/a)) = 0.7740.
    a, b, c_bar = 1.0, 20.0, 0.2
    d = math.sqrt(c_bar * math.log(b / a))
    assert_allclose(d, 0.7740, atol=5e-5)
    assert_allclose(pot.yu_pair_gain(d, a, b, c_bar), 0.0, atol=1e-14)
    # The paper's 4-digit value is within 5e-5 of the root, where |gain'| = 2 b d/c_bar
    # exp(-d^2/c_bar) = 2 a d/c_bar = 7.74, so |gain(0.7740)| < 4e-4.
    assert_allclose(pot.yu_pair_gain(0.7740, a, b, c_bar), 0.0, atol=4e-4)
    # Repulsive inside, attractive outside.
    assert pot.yu_pair_gain(0.5, a, b, c_bar) < 0.0 < pot.yu_pair_gain(0.9, a, b, c_bar)


def test_yu_pair_gain_hand_values():
    # At 0: a - b = -19; far away: a.
    assert_allclose(pot.yu_pair_gain(np.array([0.0, 100.0]), 1.0, 20.0, 0.2), [-19.0, 1.0],
                    rtol=1e-15)


@pytest.mark.parametrize('a, b, c_bar', [(1.0, 20.0, 0.2), (2.0, 5.0, 1.0)])
def test_yu_pair_potential_derivative_over_s_is_gain(a, b, c_bar):
    s = np.linspace(0.05, 3.0, 60)
    fd = central_difference(lambda x: pot.yu_pair_potential(x, a, b, c_bar), s)
    assert_allclose(fd / s, pot.yu_pair_gain(s, a, b, c_bar), rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize('shape', [(7, 2), (5, 3), (2,)])
def test_rowwise_is_broadcasting_bit_for_bit(shape):
    rng = np.random.default_rng(8)
    v = rng.normal(size=shape)
    s = rng.uniform(0.5, 2.0, size=shape[:-1])
    for op in (np.multiply, np.divide):
        assert np.array_equal(pot.rowwise(op, v, s), op(v, np.asarray(s)[..., None]))


def test_sigma_norm_and_grad_take_the_squared_norm():
    z = np.random.default_rng(9).normal(size=(6, 3))
    sq = pot.squared_norm(z)
    assert np.array_equal(pot.sigma_norm(z, 0.1, sq), pot.sigma_norm(z, 0.1))
    assert np.array_equal(pot.sigma_grad(z, 0.1, sq), pot.sigma_grad(z, 0.1))
