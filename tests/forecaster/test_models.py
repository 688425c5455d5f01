"""LTC solvers against the closed-form solution of the linear ODE they reduce to, and the models' shapes."""
import math

import pytest
import torch

from oilspill_moos.forecaster.models import KINDS, LTCCell, build_model

D = torch.float64


def linear_cell(solver: str, unfolds: int, gate: float = 0.3, tau: float = 2.0, reversal: float = 1.5,
                **kw) -> LTCCell:
    """Zero weights make f a constant sigmoid(b): dx/dt = -(1/tau + f) x + f A is then linear."""
    cell = LTCCell(3, 4, solver=solver, unfolds=unfolds, **kw).double()
    with torch.no_grad():
        cell.input_map.weight.zero_()
        cell.input_map.bias.fill_(math.log(gate / (1 - gate)))
        cell.recurrent_map.weight.zero_()
        cell.tau_raw.fill_(math.log(math.expm1(tau - cell.tau_min)))
        cell.reversal.fill_(reversal)
    return cell


def analytic(x0: torch.Tensor, t: torch.Tensor, gate=0.3, tau=2.0, reversal=1.5) -> torch.Tensor:
    rate = 1.0 / tau + gate
    steady = gate * reversal / rate
    return steady + (x0 - steady) * torch.exp(-rate * t.unsqueeze(-1))


X0 = torch.tensor([[0.0, -1.0, 2.0, 0.5], [1.0, 3.0, -2.0, 0.0]], dtype=D)
U = torch.zeros(2, 3, dtype=D)
DT = torch.tensor([1.0, 2.5], dtype=D)          # irregular elapsed time per sample


@pytest.mark.parametrize("solver,unfolds,tol", [("rk4", 20, 1e-7), ("euler", 400, 2e-3), ("fused", 400, 2e-3)])
def test_solver_matches_analytic_linear_ode(solver, unfolds, tol):
    cell = linear_cell(solver, unfolds)
    got = cell(U, X0, DT)
    assert torch.allclose(got, analytic(X0, DT), atol=tol)


@pytest.mark.parametrize("solver,order", [("rk4", 4), ("euler", 1), ("fused", 1)])
def test_solver_convergence_order(solver, order):
    want = analytic(X0, DT)
    with torch.no_grad():
        coarse = (linear_cell(solver, 8)(U, X0, DT) - want).abs().max().item()
        fine = (linear_cell(solver, 16)(U, X0, DT) - want).abs().max().item()
    assert math.log2(coarse / fine) == pytest.approx(order, abs=0.25)


def reference_solution(rhs, x0: torch.Tensor, t_end: float) -> torch.Tensor:
    """Tight adaptive Dormand-Prince: torchdiffeq when installed, else scipy's solve_ivp."""
    try:
        import torchdiffeq
    except ImportError:
        from scipy.integrate import solve_ivp
        sol = solve_ivp(lambda t, y: rhs(torch.from_numpy(y)[None])[0].numpy(), (0.0, t_end), x0[0].numpy(),
                        method="DOP853", rtol=1e-12, atol=1e-12)
        return torch.from_numpy(sol.y[:, -1])[None]
    return torchdiffeq.odeint(lambda t, x: rhs(x), x0, torch.tensor([0.0, t_end], dtype=D),
                              method="dopri5", rtol=1e-12, atol=1e-12)[-1]


def test_rk4_converges_to_a_reference_ode_solver_on_the_nonlinear_cell():
    torch.manual_seed(0)
    errors = []
    for unfolds in (20, 40):
        cell = LTCCell(3, 5, solver="rk4", unfolds=unfolds).double()
        with torch.no_grad():
            cell.recurrent_map.weight.mul_(4.0)         # make the gate clearly state-dependent
            x0, u = torch.randn(1, 5, dtype=D), torch.randn(1, 3, dtype=D)
            drive = cell.input_map(u)
            ref = reference_solution(lambda x: cell.derivative(x, drive), x0, 2.0)
            errors.append((cell(u, x0, torch.tensor([2.0], dtype=D)) - ref).abs().max().item())
        torch.manual_seed(0)
    assert errors[1] < 1e-6
    assert math.log2(errors[0] / errors[1]) == pytest.approx(4, abs=0.25)


def test_fused_stays_bounded_where_euler_blows_up():
    # h * (1/tau + f) = 5 * 0.8 = 4 > 2: explicit Euler's amplification factor is |1 - 4| = 3 per step
    dt = torch.tensor([10.0, 10.0], dtype=D)
    euler = linear_cell("euler", 2)(U, X0, dt)
    fused = linear_cell("fused", 2)(U, X0, dt)
    steady = 0.3 * 1.5 / 0.8
    assert euler.abs().max() > 5 * X0.abs().max()
    low = torch.minimum(X0, torch.full_like(X0, steady))
    high = torch.maximum(X0, torch.full_like(X0, steady))
    assert bool(((fused >= low - 1e-12) & (fused <= high + 1e-12)).all())


def test_adaptive_fused_covers_the_same_elapsed_time():
    cell = linear_cell("fused", 200, adaptive=True, max_adaptive_steps=2000)
    assert torch.allclose(cell(U, X0, DT), analytic(X0, DT), atol=2e-2)


def test_adaptive_requires_the_fused_solver():
    with pytest.raises(ValueError, match="fused"):
        LTCCell(3, 4, solver="rk4", adaptive=True)


@pytest.mark.parametrize("kind", KINDS)
def test_models_give_one_mean_and_positive_sigma_per_horizon(kind):
    torch.manual_seed(1)
    model = build_model(kind, n_features=25, n_targets=6, hidden=32, heads=4, unfolds=2).double()
    x, dt = torch.randn(3, 16, 25, dtype=D), torch.rand(3, 16, dtype=D) + 0.5
    mean, sigma = model(x, dt)
    assert mean.shape == sigma.shape == (3, 4, 6)
    assert bool((sigma > 0).all())


def test_model_rejects_nan_and_wrong_shapes():
    model = build_model("ltc-fused", n_features=25, hidden=16, heads=2, unfolds=1).double()
    x = torch.randn(1, 16, 25, dtype=D)
    x[0, 3, 2] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        model(x, torch.ones(1, 16, dtype=D))
    with pytest.raises(ValueError, match="25"):
        model(torch.randn(1, 16, 24, dtype=D), torch.ones(1, 16, dtype=D))
