"""STOMP optimizer on abstract costs: convergence, obstacle avoidance, limits, batched == looped."""

from __future__ import annotations

import pytest
import torch

from services.planner.multigoal import init_straight_lines
from services.planner.stomp import Stomp, StompConfig, StompError, finite_difference_matrix

T = 40


def _bump_target(d: int = 3) -> torch.Tensor:
    """(T, D) smooth via-point trajectory with zero end velocities (the bowl's minimum)."""
    s = torch.linspace(0, 1, T)[:, None]
    start, goal = torch.zeros(d), torch.linspace(0.5, 1.0, d)
    bump = torch.sin(torch.pi * s) ** 2 * torch.tensor([0.6, -0.4, 0.3][:d])
    return start + s * (goal - start) + bump


def _acc_cost(q: torch.Tensor, w: float) -> torch.Tensor:
    """(..., T, D) -> (..., T) w * squared acceleration per interior waypoint."""
    acc = q[..., 2:, :] - 2 * q[..., 1:-1, :] + q[..., :-2, :]
    out = torch.zeros(q.shape[:-1], dtype=q.dtype)
    out[..., 1:-1] = w * (acc**2).sum(-1)
    return out


def _blob(q: torch.Tensor) -> torch.Tensor:
    """(..., T, 2) -> (..., T) gaussian 'occupancy' blob centred on the straight line's middle."""
    return torch.exp(-((q - torch.tensor([0.5, 0.0])) ** 2).sum(-1) / (2 * 0.1**2))


def test_matrices_follow_the_paper() -> None:
    n = T - 2
    a = finite_difference_matrix(n)
    assert a.shape == (n + 2, n)
    theta = torch.randn(n, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    padded = torch.cat([torch.zeros(2, dtype=torch.float64), theta, torch.zeros(2, dtype=torch.float64)])
    acc = padded[2:] - 2 * padded[1:-1] + padded[:-2]
    assert torch.allclose(a @ theta, acc[: n + 2])
    st = Stomp(StompConfig(), (-torch.ones(2), torch.ones(2)))
    assert torch.allclose(st.M.max(0).values, torch.full((n,), 1.0 / n))
    assert torch.linalg.eigvalsh(st.R.double()).min() > 0
    cov = st.noise_chol.double() @ st.noise_chol.double().T
    assert float(cov.max()) == pytest.approx(1.0, abs=1e-4)
    # against R = A^T A built here from the acceleration itself (the noise was only compared with its own factor)
    eye = torch.eye(n, dtype=torch.float64)
    cols = [torch.cat([torch.zeros(2, dtype=torch.float64), e, torch.zeros(2, dtype=torch.float64)]) for e in eye]
    a_ref = torch.stack([(c[2:] - 2 * c[1:-1] + c[:-2])[: n + 2] for c in cols], 1)  # (N + 2, N)
    r_inv = torch.linalg.inv(a_ref.T @ a_ref)
    assert torch.allclose(st.R.double(), a_ref.T @ a_ref, atol=1e-5)
    assert torch.allclose(cov, r_inv / r_inv.max(), atol=1e-4)  # eps ~ N(0, R^-1), scaled to unit maximum
    assert torch.allclose(st.M.double(), r_inv / r_inv.max(0, keepdim=True).values / n, atol=1e-6)


def test_converges_to_the_minimum_of_a_quadratic_bowl() -> None:
    target = _bump_target()
    q0 = init_straight_lines(target[0], target[-1:], T)

    def cost(q: torch.Tensor) -> torch.Tensor:
        return ((q - target) ** 2).sum(-1)

    stomp = Stomp(StompConfig(iterations=150, noise_std=0.1, seed=3), (-2 * torch.ones(3), 2 * torch.ones(3)))
    res = stomp.optimize(q0, cost)
    initial = float(cost(q0).sum())
    assert float(res.cost[0]) < 0.01 * initial
    assert float((res.trajectories[0] - target).abs().max()) < 0.06
    assert torch.equal(res.trajectories[0, 0], target[0]) and torch.equal(res.trajectories[0, -1], target[-1])
    assert float(res.cost[0]) == pytest.approx(float(cost(res.trajectories).sum()), rel=1e-4)


def test_avoids_an_occupancy_blob_10x() -> None:
    q0 = init_straight_lines(torch.zeros(2), torch.tensor([[1.0, 0.0], [1.0, 0.05]]), T)
    stomp = Stomp(StompConfig(seed=0), (-torch.ones(2), torch.ones(2)))
    res = stomp.optimize(q0, lambda q: _blob(q) + _acc_cost(q, 10.0))
    before, after = _blob(q0).sum(-1), _blob(res.trajectories).sum(-1)
    assert torch.all(after * 10 <= before), (before, after)
    assert torch.equal(res.trajectories[:, 0], q0[:, 0]) and torch.equal(res.trajectories[:, -1], q0[:, -1])


def test_never_leaves_the_joint_limits() -> None:
    lower, upper = torch.tensor([-0.2, -0.1]), torch.tensor([1.0, 0.15])
    seen: list[torch.Tensor] = []

    def cost(q: torch.Tensor) -> torch.Tensor:  # rewards leaving the box upwards in joint 1
        seen.append(q)
        return -10 * q[..., 1] + _blob(q)

    q0 = init_straight_lines(torch.tensor([0.0, 0.1]), torch.tensor([[1.0, 0.1]]), T)
    res = Stomp(StompConfig(noise_std=0.5, iterations=30), (lower, upper)).optimize(q0, cost)
    for q in [*seen, res.trajectories]:
        assert torch.all(q >= lower) and torch.all(q <= upper)
    assert float(res.trajectories[0, T // 2, 1]) > 0.14  # pushed up to the limit


def test_batched_equals_looped_with_the_same_seeds() -> None:
    goals = torch.tensor([[1.0, 0.0], [1.0, 0.2], [0.8, -0.3]])
    q0 = init_straight_lines(torch.zeros(2), goals, T)
    stomp = Stomp(StompConfig(iterations=25), (-torch.ones(2), torch.ones(2)))

    def cost(q: torch.Tensor) -> torch.Tensor:
        return _blob(q) + _acc_cost(q, 10.0)

    batched = stomp.optimize(q0, cost, seeds=[11, 12, 13])
    for k, seed in enumerate([11, 12, 13]):
        single = stomp.optimize(q0[k : k + 1], cost, seeds=[seed])
        assert torch.allclose(batched.trajectories[k], single.trajectories[0], atol=1e-5)
        assert torch.allclose(batched.history[:, k], single.history[:, 0], rtol=1e-4, atol=1e-6)
    again = stomp.optimize(q0, cost, seeds=[11, 12, 13])
    assert torch.equal(again.trajectories, batched.trajectories)  # deterministic


def test_noise_has_the_paper_covariance_and_each_goal_its_own_stream() -> None:
    """eps ~ N(0, sigma^2 R^-1 / max): per goal its seed's draw alone (batched == looped), empirical covariance."""
    d = 2
    stomp = Stomp(StompConfig(iterations=40, rollouts=50, waypoints=10, noise_std=0.2, noise_decay=1.0),
                  (torch.full((d,), -9.0), torch.full((d,), 9.0)))
    eps = stomp.sample_noise(3, [11, 12, 13])  # (I, K, R, N, D)
    assert eps.shape == (40, 3, 50, 8, d)
    for k, seed in enumerate([11, 12, 13]):
        assert torch.equal(eps[:, k], stomp.sample_noise(1, [seed])[:, 0])
    assert not torch.equal(eps[:, 0], eps[:, 1])
    x = eps[..., 0].reshape(-1, 8).double()  # samples of one joint's waypoint vector
    cov = x.T @ x / x.shape[0]
    target = 0.2**2 * stomp.noise_chol.double() @ stomp.noise_chol.double().T
    assert torch.allclose(cov, target, atol=0.004), float((cov - target).abs().max())


def test_bad_input_raises_a_named_error() -> None:
    stomp = Stomp(StompConfig(iterations=2), (-torch.ones(2), torch.ones(2)))
    q0 = init_straight_lines(torch.zeros(2), torch.tensor([[0.5, 0.5]]), T)
    with pytest.raises(StompError, match="shape"):
        stomp.optimize(q0[:, :10], _blob)
    bad = q0.clone()
    bad[0, 3, 1] = float("nan")
    with pytest.raises(StompError, match="NaN"):
        stomp.optimize(bad, _blob)
    outside = q0.clone()
    outside[0, 0, 0] = 1.5
    with pytest.raises(StompError, match="outside the joint limits"):
        stomp.optimize(outside, _blob)
    with pytest.raises(StompError, match="cost callable"):
        stomp.optimize(q0, lambda q: q.sum(-1).sum(-1))
    with pytest.raises(StompError, match="rollouts"):
        Stomp(StompConfig(rollouts=1), (-torch.ones(2), torch.ones(2)))


def test_nan_costs_do_not_poison_the_trajectory() -> None:
    def cost(q: torch.Tensor) -> torch.Tensor:
        c = _blob(q)
        return torch.where(q[..., 1] > 0.2, torch.full_like(c, float("nan")), c)

    q0 = init_straight_lines(torch.zeros(2), torch.tensor([[1.0, 0.0]]), T)
    res = Stomp(StompConfig(iterations=20), (-torch.ones(2), torch.ones(2))).optimize(q0, cost)
    assert torch.isfinite(res.trajectories).all()


def test_anytime_interrupt_stops_after_min_iterations_with_the_same_prefix() -> None:
    target = _bump_target()
    q0 = init_straight_lines(target[0], target[-1:], T)

    def cost(q: torch.Tensor) -> torch.Tensor:
        return ((q - target) ** 2).sum(-1)

    stomp = Stomp(StompConfig(iterations=30, seed=3), (-2 * torch.ones(3), 2 * torch.ones(3)))
    full = stomp.optimize(q0, cost)
    asked: list[int] = []

    def waiting() -> bool:  # a newer input is always waiting
        asked.append(1)
        return True

    cut = stomp.optimize(q0, cost, interrupt=waiting, min_iterations=10)
    assert full.history.shape[0] == 31 and cut.history.shape[0] == 11 and len(asked) == 1
    assert torch.equal(cut.history[:10], full.history[:10])  # the same iterations, stopped early
    assert float(cut.cost[0]) > float(full.cost[0])  # fewer iterations: a higher cost, still better than q0
    assert float(cut.cost[0]) < float(cost(q0).sum())
    never = stomp.optimize(q0, cost, interrupt=lambda: False, min_iterations=1)
    assert torch.equal(never.trajectories, full.trajectories)


@pytest.mark.parametrize("reuse", [0, 5])
def test_compiled_steps_equal_eager(reuse: int) -> None:
    """``compile``: the rollout and update steps as torch.compile graphs give eager's numbers to rounding."""
    target = _bump_target()

    def cost(q: torch.Tensor) -> torch.Tensor:
        return ((q - target) ** 2).sum(-1) + _acc_cost(q, 1.0) + 0.2 * _blob(q[..., :2])

    q0 = init_straight_lines(target[0], torch.stack([target[-1], target[-1] * 0.8]), T)
    bounds = (-torch.ones(3) * 2, torch.ones(3) * 2)
    runs = {flag: Stomp(StompConfig(iterations=30, noise_std=0.05, compile=flag, rollouts=10 if reuse else 16,
                                    reuse=reuse), bounds) for flag in (False, True)}
    for s in runs.values():
        s.warm_up(2)
    if not runs[True].compiled:
        pytest.skip("torch.compile is not available here (no C++ compiler): STOMP fell back to eager")
    eager, compiled = (runs[f].optimize(q0, cost) for f in (False, True))
    assert runs[True].compiled  # still compiled after the run (no fallback midway)
    torch.testing.assert_close(compiled.history, eager.history, rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(compiled.trajectories, eager.trajectories, rtol=1e-4, atol=1e-4)
    assert float(compiled.history[-1].sum()) < 0.5 * float(compiled.history[0].sum())  # it did optimise


def test_reused_rollouts_are_the_previous_iterations_best_with_their_costs() -> None:
    q0 = init_straight_lines(torch.zeros(2), torch.tensor([[1.0, 0.0]]), T)
    stomp = Stomp(StompConfig(rollouts=10, reuse=5, iterations=4, seed=0), (-torch.ones(2), torch.ones(2)))
    calls: list[int] = []
    updates: list[tuple[torch.Tensor, ...]] = []

    def cost(q: torch.Tensor) -> torch.Tensor:
        calls.append(q.shape[1])
        return _blob(q) + _acc_cost(q, 10.0)

    step = stomp._step

    def spy(name: str, *args: object) -> tuple[torch.Tensor, ...]:
        if name == "update":
            updates.append(tuple(a.clone() if isinstance(a, torch.Tensor) else a for a in args[:3]))
        return step(name, *args)

    stomp._step = spy  # type: ignore[method-assign]
    res = stomp.optimize(q0, cost)
    assert calls == [11, 6, 6, 6, 1]  # theta + 10 rollouts, then theta + 5 new ones per iteration: 29 vs 44 costed
    for prev, cur in zip(updates, updates[1:], strict=False):
        theta0, eps0, cost0 = prev
        theta1, eps1, cost1 = cur
        order = torch.argsort(cost0[:, 1:].sum(-1), dim=1)[0, :5]
        # the last 5 rollouts of an iteration are the best 5 of the one before, as trajectories and with their costs
        torch.testing.assert_close(theta1[0] + eps1[0, 5:], theta0[0] + eps0[0, order])
        assert torch.equal(cost1[0, 6:], cost0[0, 1:][order])
    assert bool(torch.isfinite(res.cost).all())


def test_reuse_must_leave_new_rollouts() -> None:
    with pytest.raises(StompError, match="stomp.reuse"):
        Stomp(StompConfig(rollouts=4, reuse=4), (-torch.ones(2), torch.ones(2)))


def test_one_goal_s_first_step_compiles_nothing_the_warm_up_did_not() -> None:
    """With one goal (K = 1) the start sliced from the path kept the path's stride on its size-1 axis, another than
    the warm-up's, and the first real step compiled STOMP's steps again: 0.4-0.6 s of a real-time run's first plan
    (the demo plans for one cup)."""
    target = _bump_target()
    stomp = Stomp(StompConfig(iterations=3, compile=True, rollouts=10, reuse=5),
                  (-torch.ones(3) * 2, torch.ones(3) * 2))
    stomp.warm_up(1)
    if not stomp.compiled:
        pytest.skip("torch.compile is not available here (no C++ compiler): STOMP fell back to eager")
    # a recompile fails the step (then eager); dynamo's own patch (pytest's monkeypatch hid the option on undo)
    with torch._dynamo.config.patch(error_on_recompile=True):
        stomp.optimize(init_straight_lines(target[0], target[-1:], T), lambda q: ((q - target) ** 2).sum(-1))
    assert stomp.compiled
