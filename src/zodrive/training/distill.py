"""`robust-train --method distill`: adversarially robust distillation of a DQN driver.

Why: SA-DQN and Algorithm 2 continue TD learning, and under this reward TD learning drifts to
the always-SLOWER fixed point (a constant decision is the cheapest robust one; measured in
the README). Distillation keeps the driver's behaviour as the target instead: collect the
states the teacher visits, then train a student (initialized as the teacher) to take the
teacher's action at every state *and* everywhere in the eps-ball around it (Madry-style
adversarial training on the supervised loss, the inner max by `pgd_steps` signed-gradient
steps inside the threat model: box, frozen presence):

    loss = CE(student(x), a*) + kappa * max_{x' in B(x, eps)} CE(student(x'), a*),  a* = argmax teacher(x)

Cf. policy distillation (Rusu et al., ICLR 2016) and adversarial training (Madry et al., ICLR
2018). The student is written as an ordinary SB3 DQN zip (the teacher's zip with the Q-network
weights replaced), so every command reads it; its outputs are logits, not Q-values.

With `teacher` set to an observation-reading baseline (`baseline:rules`,
`baseline:robust-rules@EPS`), that driver drives and labels instead: a student of a better
driver than the source model, made robust the same way (the student keeps the source model's
network shape and zip).

With `dagger` the student is cloned with DAgger (`dagger_distill`): into a DQN's Q-network, or
into a DDPG/TD3 actor (regression on the tanh-squashed action) from `baseline:idm-mobil`, a
teacher that reads the simulator and so labels states only as they are driven through (as
`baseline:planner`, the look-ahead teacher of a DQN student).
"""

from __future__ import annotations

import copy
import io
import time
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, cast

import numpy as np
import torch
from torch.nn import functional as F

from zodrive.attacks.threat import ThreatModel, worst_in_ball
from zodrive.attacks.victim import ActionKind, Victim
from zodrive.compute import one_torch_thread
from zodrive.drivers.baselines import check_baseline_fits, driver_victim, simulator_driver
from zodrive.envs import action_names, attack_context, make_env, n_actions, observation_shape
from zodrive.errors import ZodriveError
from zodrive.evaluation.rollout import act, clean_states, states_driven, to_action
from zodrive.policies.loading import load_network, model_file
from zodrive.policies.policy import resolve
from zodrive.policies.safe_load import PolicyNetwork
from zodrive.policies.victims import network_victim
from zodrive.runinfo import write_json, write_run_info

if TYPE_CHECKING:
    import gymnasium as gym


Augment = Callable[[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]
Criterion = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


@one_torch_thread  # small MLPs: one thread is fastest, and the result does not depend on the load
def distill(model: str, preset: dict[str, Any], eps: float | None, steps: int, out: Path, *, seed: int = 1,
            kappa: float = 1.0, pgd_steps: int = 5, epochs: int = 20, force: bool = False,
            teacher: str | None = None, dagger: int | None = None) -> Path:
    """Collect `steps` teacher states (training seeds `seed`, `seed` + 1, ...), train the
    robust student (initialized as `model`; the teacher is `model` itself unless `teacher`
    names an observation-reading baseline), write `out/model.zip` and `out/train.json`;
    returns the zip's path. With `dagger` (rounds >= 0) the student is trained by `dagger_distill`
    instead (this path is unchanged without it). `eps` None: plain cloning (`kappa` must be 0)."""

    if (out / "model.zip").exists() and not force:
        raise ZodriveError(f"{out} already holds a model; use --force to overwrite it")
    source = load_network(model, preset)
    if source.algo not in ("dqn", "ddpg"):
        raise ZodriveError(f"--method distill is implemented for DQN and DDPG/TD3 models, not {source.algo}")
    if source.algo == "ddpg" and (dagger is None or teacher is None):
        raise ZodriveError("--method distill on a DDPG/TD3 model clones a --teacher with --dagger ROUNDS "
                           "(e.g. --teacher baseline:idm-mobil --dagger 4 --kappa 0)")
    readers = ("observation", "simulator") if dagger is not None else ("observation",)
    taught = resolve(teacher).baseline if teacher is not None else None
    if teacher is not None and not (taught is not None and taught.reads in readers):
        also = " or, with --dagger, baseline:idm-mobil or baseline:planner" if dagger is not None else ""
        raise ZodriveError("--teacher must be an observation-reading baseline (baseline:rules, "
                           f"baseline:robust-rules@EPS){also}, not {teacher!r}")
    if taught is not None:
        check_baseline_fits(taught, preset)
    if dagger is not None:
        return dagger_distill(model, preset, eps, steps, out, teacher=teacher, rounds=dagger, seed=seed,
                              kappa=kappa, pgd_steps=pgd_steps, epochs=epochs)
    guide, env = teacher_and_env(teacher, source, preset)
    start = time.perf_counter()
    torch.manual_seed(seed)
    states = clean_states(env, guide, seed, steps)
    env.close()
    mask, low, high = _mask_and_box(eps, preset, states.shape[1:])
    x_all = torch.as_tensor(states, dtype=torch.float32)
    y_all = torch.as_tensor(guide.query(states).argmax(axis=1), dtype=torch.long)
    assert isinstance(source.net, torch.nn.Sequential)  # a DQN's network is its MLP alone (`network_from`)
    student = copy.deepcopy(source.net).train()
    opt = torch.optim.Adam(student.parameters(), lr=3e-4)
    gen = torch.Generator().manual_seed(seed)
    history = []
    for epoch in range(epochs):
        order = torch.randperm(len(x_all), generator=gen)
        total = 0.0
        for batch in order.split(256):
            x, y = x_all[batch], y_all[batch]
            loss = F.cross_entropy(student(x.reshape(len(x), -1)), y)  # without eps: plain cloning
            if eps is not None:  # (with kappa 0 and an eps the PGD still runs: results made so stay as they were)
                x_adv = worst_in_ball(lambda z: F.cross_entropy(student(z.reshape(len(z), -1)), y, reduction="none"),
                                      x, eps, pgd_steps, mask, low, high)
                loss = loss + kappa * F.cross_entropy(student(x_adv.reshape(len(x), -1)), y)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * len(batch)
        history.append(round(total / len(x_all), 4))
    student.eval()
    with torch.no_grad():
        agree = float((student(x_all.reshape(len(x_all), -1)).argmax(dim=1) == y_all).float().mean())
    method = {"name": "robust-distillation", "teacher": teacher or "the source model", "eps": eps, "kappa": kappa,
              "pgd_steps": pgd_steps, "epochs": epochs, "states": steps,
              "reference": "Rusu et al. 2016; Madry et al. 2018"}
    return _save(out, model, preset, seed, method, student, "dqn", start, steps,
                 {"loss_per_epoch": history, "clean_agreement": round(agree, 4)})


def _save(out: Path, model: str, preset: dict[str, Any], seed: int, method: dict[str, Any],
          student: torch.nn.Sequential, algo: str, start: float, total: int, record: dict[str, Any]) -> Path:
    """Write the run's record, the student's zip (`_write_zip`) and train.json (with `record`); the zip's path."""
    source = model_file(model)
    write_run_info(out, {"source_model": str(source), "preset": preset, "method": method}, seed)
    _write_zip(source, student, out / "model.zip", algo)
    wall = time.perf_counter() - start
    write_json(out / "train.json", {
        "algo": algo, "kind": "distill", "source_model": str(source), "method": method, "total_timesteps": total,
        "seed": seed, **record, "wall_time_s": round(wall, 1), "steps_per_s": round(total / wall, 1)})
    return out / "model.zip"


def _mask_and_box(eps: float | None, preset: dict[str, Any], shape: tuple[int, ...]) -> tuple[torch.Tensor, Any, Any]:
    """The mask (frozen presence) of the threat model the noise and the adversarial term use, for
    observations of `shape`, and the observation box (low, high); without `eps` (plain cloning)
    only the mask is read."""
    context = attack_context(preset)
    features = context["features"]
    threat = ThreatModel(features=features) if eps is None else ThreatModel(eps=eps, features=features)
    return torch.as_tensor(threat.mask(shape)), *context["bounds"]


ACTING_PREFIXES = {"dqn": ("q_net.q_net", "q_net_target.q_net"), "ddpg": ("actor.mu", "actor_target.mu")}


ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # every member of a written zip: the earliest date a zip can hold


def _torch_bytes(obj: Any) -> bytes:
    """`obj` as `torch.save` writes it: a zip member's bytes."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _write_zip(source: Path, student: torch.nn.Sequential, target: Path, algo: str = "dqn") -> None:
    """The source's SB3 zip with its acting network's (and target network's) weights replaced:
    the Q-network of a DQN, the actor of a DDPG/TD3 (whose critic and optimizer states stay
    as they were: SB3's loader needs them, and nothing acts on them). A DQN's optimizer keeps its
    settings and loses its moments (they were the teacher's), so `DQN.load` reads the student."""
    with zipfile.ZipFile(source) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    weights = torch.load(io.BytesIO(members["policy.pth"]), map_location="cpu", weights_only=True)
    layers = [m for m in student if isinstance(m, torch.nn.Linear)]
    for prefix in ACTING_PREFIXES[algo]:
        depth = prefix.count(".") + 1
        indices = sorted({int(k.split(".")[depth]) for k in weights if k.startswith(prefix + ".")})
        if len(indices) != len(layers):
            raise ZodriveError(f"{source}: unexpected {prefix} layout")
        for index, layer in zip(indices, layers):
            weights[f"{prefix}.{index}.weight"] = layer.weight.detach().clone()
            weights[f"{prefix}.{index}.bias"] = layer.bias.detach().clone()
    members["policy.pth"] = _torch_bytes(weights)
    if algo == "dqn" and "policy.optimizer.pth" in members:
        # the teacher's Adam moments belong to its weights, not the student's: keep the optimizer's settings
        # (SB3's loader needs the member) with no moments, as a freshly built optimizer has
        optimizer = torch.load(io.BytesIO(members["policy.optimizer.pth"]), map_location="cpu", weights_only=True)
        optimizer["state"] = {}
        members["policy.optimizer.pth"] = _torch_bytes(optimizer)
    tmp = target.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():  # a fixed date: the same seed gives the same SHA-256
            archive.writestr(zipfile.ZipInfo(name, date_time=ZIP_DATE), data, compress_type=zipfile.ZIP_DEFLATED)
    tmp.replace(target)


# --- behaviour cloning with DAgger (`--dagger ROUNDS`) -------------------------------------------

class Standardize(torch.nn.Module):
    """Fixed input layer x -> (x - mean) / std (a constant feature keeps std 1). Affine, so
    `folded` merges it into the first Linear layer and the saved network is the plain MLP."""

    mean: torch.Tensor  # buffers (register_buffer)
    std: torch.Tensor

    def __init__(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        super().__init__()
        self.register_buffer("mean", mean.float())
        self.register_buffer("std", torch.where(std > 1e-6, std, torch.ones_like(std)).float())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std


def standardized(net: torch.nn.Sequential, x: torch.Tensor | None = None) -> torch.nn.Sequential:
    """`Standardize` in front of a copy of `net`, computing exactly what `net` does: with
    statistics of the flat batch `x` (`restandardize`), or the identity until then. Why: the
    rules' thresholds are on differences of small normalized numbers (a lane is 0.04 of the y
    range, the "centred" test 0.005); in standardized coordinates every feature moves the
    first layer on the scale of its data (alone it helps the fit little:
    results/imitation/ablation.txt)."""
    n = next(m for m in net if isinstance(m, torch.nn.Linear)).in_features
    out = torch.nn.Sequential(Standardize(torch.zeros(n), torch.ones(n)), *copy.deepcopy(net))
    if x is not None:
        restandardize(out, x)
    return out


def restandardize(net: torch.nn.Sequential, x: torch.Tensor, floor: float = 0.0) -> None:
    """In place: `net[0]` (a `Standardize`) takes the statistics of `x` (each std at least
    `floor`) and the first Linear layer is rescaled so that `net` still computes the same function."""
    scale = cast(Standardize, net[0])
    new = Standardize(x.mean(dim=0), x.std(dim=0).clamp(min=floor))
    first = next(m for m in net if isinstance(m, torch.nn.Linear))
    with torch.no_grad():
        first.bias.add_(first.weight @ ((new.mean - scale.mean) / scale.std))
        first.weight *= new.std / scale.std
        scale.mean.copy_(new.mean)
        scale.std.copy_(new.std)


def folded(net: torch.nn.Sequential) -> torch.nn.Sequential:
    """`net` without its leading `Standardize`, merged into the first Linear layer (the same
    function, as the plain MLP an SB3 zip holds)."""
    scale = net[0]
    if not isinstance(scale, Standardize):
        return net
    body = copy.deepcopy(torch.nn.Sequential(*list(net)[1:]))
    first = next(m for m in body if isinstance(m, torch.nn.Linear))
    with torch.no_grad():
        first.weight /= scale.std
        first.bias.sub_(first.weight @ scale.mean)
    return body


def class_weights(y: torch.Tensor, n_classes: int, power: float) -> torch.Tensor:
    """Cross-entropy weights (count_c / count_mean) ** -power, 1 on average over the samples;
    power 0 is the plain loss, 0.5 lifts the rare lane changes without drowning IDLE."""
    counts = torch.bincount(y, minlength=n_classes).float().clamp(min=1)
    w = (counts / counts.mean()) ** -power
    return w / (w[y].mean())


def jitter(label: Callable[[torch.Tensor], torch.Tensor], std: torch.Tensor, scale: float, low: float, high: float,
           gen: torch.Generator) -> Augment:
    """A batch augmentation for `fit`: (x, y) -> x and y followed by a copy of x with Gaussian
    noise of `std` (per flat feature; 0 where nothing may change) times a per-state factor drawn
    from U(0, `scale`), kept in [low, high], and labelled by `label` (flat states -> actions).
    Why: the rules are a function of the observation, so any state can be labelled; the
    states of one episode are nearly the same, and without this the network fits features
    that merely co-occur with braking in the few car-following episodes it saw
    (results/imitation/ablation.txt)."""

    def augment(x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        factor = torch.rand(len(x), 1, generator=gen) * scale
        noisy = (x + torch.randn(x.shape, generator=gen) * std * factor).clamp(low, high)
        return torch.cat([x, noisy]), torch.cat([y, label(noisy)])

    return augment


def fit(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, *, epochs: int, lr: float, batch: int,
        weight: torch.Tensor | None, gen: torch.Generator, robust: dict[str, Any] | None = None,
        augment: Augment | None = None, criterion: Criterion | None = None) -> list[float]:
    """Adam on (weighted) cross-entropy over flat states `x` and labels `y` (or on `criterion`
    (output, target), e.g. `scaled_mse` for continuous actions), the learning rate
    cosine-annealed to 0 over `epochs`; each batch passes through `augment` (e.g. `jitter`) if
    given; with `robust` (eps, kappa, pgd_steps, mask, low, high) the adversarial CE of
    `distill` is added (discrete labels only). Returns the mean loss per epoch (over the
    batches as augmented)."""

    if criterion is not None and robust and robust["kappa"] > 0:
        raise ZodriveError("the adversarial term is implemented for discrete labels (cross-entropy) only")
    net.train()
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs * -(-len(x) // batch))
    history = []
    for _ in range(epochs):
        total = 0.0
        for idx in torch.randperm(len(x), generator=gen).split(batch):
            xb, yb = x[idx], y[idx]
            if augment is not None:
                xb, yb = augment(xb, yb)
            loss = F.cross_entropy(net(xb), yb, weight=weight) if criterion is None else criterion(net(xb), yb)
            if robust and robust["kappa"] > 0:
                shape = (len(xb), *robust["mask"].shape)
                x_adv = worst_in_ball(lambda z: F.cross_entropy(net(z.reshape(len(z), -1)), yb, reduction="none"),
                                      xb.reshape(shape), robust["eps"], robust["pgd_steps"], robust["mask"],
                                      robust["low"], robust["high"])
                loss = loss + robust["kappa"] * F.cross_entropy(net(x_adv.reshape(len(xb), -1)), yb, weight=weight)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(idx)
        history.append(round(total / len(x), 4))
    net.eval()
    return history


def agreement(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, names: tuple[str, ...]) -> dict[str, Any]:
    """Share of states where `net`'s argmax is the label: overall and per label class
    (agreement, count)."""
    with torch.no_grad():
        hit = net(x).argmax(dim=1) == y
    per = {name: [round(float(hit[y == c].float().mean()), 4), int((y == c).sum())]
           for c, name in enumerate(names) if (y == c).any()}
    return {"all": round(float(hit.float().mean()), 4), "count": len(y), "per_class": per}


def scaled_mse(scale: torch.Tensor) -> Criterion:
    """MSE per action dimension divided by `scale` ** 2, averaged over the dimensions. Why: the
    teacher's steering is mostly far smaller than its acceleration, and it decides off-road and
    lane changes; scaled, both dimensions count alike (on IDM + MOBIL's own states the held-out
    fit came out the same as with the plain MSE: results/imitation-continuous/ablation.txt)."""
    weight = 1.0 / scale.clamp(min=1e-3) ** 2

    def criterion(out: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return ((out - target) ** 2 * weight).mean()

    return criterion


def scaled_l1(scale: torch.Tensor) -> Criterion:
    """Mean absolute error per action dimension divided by `scale`, averaged over the dimensions.
    Why: an observation-reading teacher's lane change is a decision, and a regression of a
    decision onto states that look alike learns its mean (half a lane change, i.e. drifting);
    the absolute error learns its median (keep the lane unless most such states change), and
    fits the small lane-keeping corrections five times more closely (scratch fit on 20000 of
    the continuous rules' states: calm-state steering error 0.0057 against 0.026 with `scaled_mse`)."""
    weight = 1.0 / scale.clamp(min=1e-3)

    def criterion(out: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return ((out - target).abs() * weight).mean()

    return criterion


def action_error(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, names: tuple[str, ...]) -> dict[str, Any]:
    """How far `net`'s continuous action is from the labels `y`, per action dimension: RMSE,
    mean absolute error and the labels' standard deviation (what a constant would score)."""
    with torch.no_grad():
        err = net(x) - y
    per = {name: {"rmse": round(float(err[:, i].pow(2).mean().sqrt()), 4),
                  "mae": round(float(err[:, i].abs().mean()), 4),
                  "label_std": round(float(y[:, i].std()), 4)} for i, name in enumerate(names)}
    return {"count": len(y), "per_dim": per}


DAGGER_LR, DAGGER_BATCH = 1e-3, 256   # Adam, cosine-annealed per refit (results/imitation/ablation.txt)
DAGGER_WEIGHT_POWER = 0.0             # class weights (count / mean) ** -power; see `class_weights`
DAGGER_JITTER = 0.5                   # `jitter` scale (in standard deviations of round 0's states)


def labelled_rollout(env: gym.Env, teacher: Victim, student: Victim, beta: float, seed: int, count: int,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """`count` states of the mixture policy (at each step the teacher's action with
    probability `beta`, else the student's) from `env.reset(seed=seed)`, an episode that ends
    followed by a reset with seed `seed + states so far` (`states_driven`), and the teacher's
    outputs at each of them. The teacher is asked exactly once per step, while its state is the
    one it labels: a simulator-reading teacher (`baseline:idm-mobil`) reads the simulator then,
    and its own memory (target lane, decision timer) follows the episode whoever drives."""

    labels = []

    def choose(obs: np.ndarray) -> Any:
        out = teacher.query(obs[None])
        labels.append(out[0])
        return to_action(teacher, out, env.action_space) if rng.random() < beta else act(student, obs, env.action_space)

    return states_driven(env, choose, seed, count), np.stack(labels)


def targets(outputs: np.ndarray, kind: str) -> torch.Tensor:
    """Training targets from a teacher's outputs: the chosen class (discrete) or the action."""
    if kind == "discrete":
        return torch.as_tensor(outputs.argmax(axis=1), dtype=torch.long)
    return torch.as_tensor(outputs, dtype=torch.float32)


def dagger_rounds(env: gym.Env, teacher: Victim, student: torch.nn.Sequential, obs_shape: tuple[int, ...], *,
                  rounds: int, steps: int, seed: int,
                  refit: Callable[[torch.nn.Sequential, torch.Tensor, torch.Tensor], list[float]],
                  evaluate: Callable[[torch.nn.Sequential, torch.Tensor, torch.Tensor], dict[str, Any]],
                  kind: ActionKind = "discrete", beta: float = 0.0,
                  ) -> tuple[torch.Tensor, torch.Tensor, list[dict[str, Any]]]:
    """DAgger (Ross et al., AISTATS 2011): round r collects `steps` states of the mixture that
    takes the teacher's action with probability beta ** r (round 0: the teacher drives; beta 0:
    pure student rollouts after it) on seeds [seed + r steps, seed + (r + 1) steps); every
    state is labelled with the teacher's output as it drove by (`labelled_rollout`), added to
    the aggregate, and `refit(student, x, y)` trains on the whole aggregate. `evaluate(student)`
    after each refit goes into the round's record. Returns the aggregate (flat states,
    targets) and the records."""

    xs: list[torch.Tensor] = []
    ys: list[torch.Tensor] = []
    records = []
    for r in range(rounds + 1):
        mix = beta ** r
        states, outputs = labelled_rollout(env, teacher, network_victim(student, kind, obs_shape), mix,
                                           seed + r * steps, steps, np.random.default_rng([seed, r]))
        xs.append(torch.as_tensor(states.reshape(len(states), -1), dtype=torch.float32))
        ys.append(targets(outputs, kind))
        x, y = torch.cat(xs), torch.cat(ys)
        losses = refit(student, x, y)
        driver = "teacher" if mix == 1 else "student" if mix == 0 else f"mixture (teacher's action w.p. {mix:.3g})"
        records.append({"round": r, "driver": driver, "beta": mix, "seeds": [seed + r * steps,
                        seed + (r + 1) * steps - 1], "aggregate": len(x), "loss_per_epoch": losses,
                        **evaluate(student, x, y)})
    return torch.cat(xs), torch.cat(ys), records


def teacher_and_env(teacher: str | None, source: PolicyNetwork, preset: dict[str, Any]) -> tuple[Victim, gym.Env]:
    """The labeller and the environment the rounds drive: a simulator-reading baseline (IDM +
    MOBIL, re-planning where the student drove it into a lane it did not choose:
    `IdmMobilDriver(replan=True)`) is bound to that very environment (it reads its vehicles);
    otherwise the observation-reading baseline, or the source network itself, beside a fresh
    environment."""

    baseline = resolve(teacher).baseline if teacher is not None else None
    if baseline is not None and baseline.reads == "simulator":
        env = make_env(preset)
        driver = simulator_driver(baseline, env, preset, source.kind, replan=True)
        return driver_victim(driver, source.kind, observation_shape(preset), n_actions(preset)), env
    guide = resolve(teacher).victim(preset) if teacher else network_victim(source.net, source.kind, source.obs_shape)
    return guide, make_env(preset)


def reinitialized(net: torch.nn.Sequential) -> torch.nn.Sequential:
    """A copy of `net` with every Linear layer freshly initialized (torch's default, from the
    global generator). Why: a DDPG actor's trained weights are a bad start for regression; its
    saturated outputs survive off the cloned states (results/imitation-continuous/README.md)."""
    out = copy.deepcopy(net)
    for layer in out:
        if isinstance(layer, torch.nn.Linear):
            layer.reset_parameters()
    return out


DAGGER_EGO_JITTER = 0.2  # continuous: the ego row's share of the `jitter` noise (1: as much as the others; 0:
                         # none, which on the tuning seeds changed lanes like the teacher but collided in 10-15 %)
DAGGER_BETA = 0.5         # continuous: round r rolls out the teacher's action with probability 0.5 ** r
DAGGER_STD_FLOOR = 0.05   # continuous: the input scale's smallest std (normalized units; a lane is 0.04): the
                          # ego's speed feature is nearly constant (clipped at 20 m/s); no effect measured
                          # (ablation.txt)


@one_torch_thread
def dagger_distill(model: str, preset: dict[str, Any], eps: float | None, steps: int, out: Path, *,
                   teacher: str | None, rounds: int, seed: int, kappa: float, pgd_steps: int,
                   epochs: int) -> Path:
    """`distill` with DAgger: the student (the source model's network, behind a standardized
    input layer that is folded away before saving) is refit for `epochs` epochs on the
    aggregate after each of `rounds` + 1 rounds of `steps` states (`dagger_rounds`).
    Discrete (DQN): cross-entropy, pure student rollouts after round 0, every batch with a
    `jitter` copy labelled by the (observation-reading) teacher, and the adversarial term when
    `kappa` > 0. Continuous (DDPG/TD3 actor, re-initialized: `reinitialized`): `scaled_mse` on the
    tanh-squashed action, scaled per dimension by round 0's label spread, mixture rollouts (`DAGGER_BETA`); for an
    observation-reading teacher (the continuous `baseline:rules`) the `jitter` copy and
    `scaled_l1` instead (a simulator-reading one, IDM + MOBIL, labels only the states it is
    driven through). Agreement (or the
    action error) is measured after each round on the aggregate (train) and on states no round
    trained on: `steps // 2` the teacher drives into and `steps // 2` the current student drives
    into, on the seeds after the training ones. Writes `out/model.zip` (a plain SB3 zip of the
    source's algorithm) and `out/train.json`."""

    if rounds < 0 or steps < 2:
        raise ZodriveError(f"DAgger needs rounds >= 0 and steps >= 2, not {rounds} and {steps}")
    source = load_network(model, preset)
    kind = source.kind
    if kind == "continuous" and kappa > 0:
        raise ZodriveError("--kappa > 0 (the adversarial term) is implemented for DQN students; use --kappa 0")
    if not isinstance(source.net, torch.nn.Sequential):  # e.g. an actor rescaled to a box other than [-1, 1]
        raise ZodriveError(f"{model}: DAgger clones plain MLPs acting in [-1, 1]; this policy rescales its output")
    names = tuple(action_names(preset))
    start = time.perf_counter()
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    guide, env = teacher_and_env(teacher, source, preset)
    held_seed = seed + (rounds + 1) * steps  # after every training seed
    held, held_out = labelled_rollout(env, guide, guide, 1.0, held_seed, steps // 2, np.random.default_rng(held_seed))
    x_held = torch.as_tensor(held.reshape(len(held), -1), dtype=torch.float32)
    y_held = targets(held_out, kind)
    mask, low, high = _mask_and_box(eps, preset, source.obs_shape)
    robust = {"eps": eps, "kappa": kappa, "pgd_steps": pgd_steps, "low": low, "high": high, "mask": mask}
    # the identity scale until the first refit sets it from round 0's states
    student = standardized(source.net if kind == "discrete" else reinitialized(source.net))
    measure = agreement if kind == "discrete" else action_error
    beta = 0.0 if kind == "discrete" else DAGGER_BETA
    reads_observation = guide.reads == "observation"  # it can label any state, and its decisions are sharp
    jittered = DAGGER_JITTER > 0 and reads_observation
    continuous_loss = ("absolute error on the tanh-squashed action, per dimension / round 0's label std"
                       if reads_observation else
                       "MSE on the tanh-squashed action, per dimension / (round 0's label std) ** 2")

    def label(flat: torch.Tensor) -> torch.Tensor:
        return targets(guide.query(flat.numpy().reshape(len(flat), *source.obs_shape)), kind)

    setup: dict[str, Any] = {}

    def refit(net: torch.nn.Sequential, x: torch.Tensor, y: torch.Tensor) -> list[float]:
        if not setup:  # round 0: the teacher's states set the input scale, the noise and the target scale
            restandardize(net, x, DAGGER_STD_FLOOR if kind == "continuous" else 0.0)
            std = x.std(dim=0) * robust["mask"].reshape(-1)  # frozen features (presence) stay as observed
            if kind == "continuous":  # less noise on the ego row: its offset from the lane centre, within 0.5 m,
                std[: source.obs_shape[-1]] *= DAGGER_EGO_JITTER  # decides the steering (a lane's width drowns it)
            setup["augment"] = jitter(label, std, DAGGER_JITTER, low, high, gen) if jittered else None
            loss = scaled_l1 if reads_observation else scaled_mse  # the median of a teacher's decisions
            setup["criterion"] = loss(y.std(dim=0)) if kind == "continuous" else None
        weight = (class_weights(y, len(names), DAGGER_WEIGHT_POWER)
                  if DAGGER_WEIGHT_POWER and kind == "discrete" else None)
        return fit(net, x, y, epochs=epochs, lr=DAGGER_LR, batch=DAGGER_BATCH, weight=weight, gen=gen,
                   robust=robust if kind == "discrete" else None, augment=setup["augment"],
                   criterion=setup["criterion"])

    def evaluate(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor) -> dict[str, Any]:
        own, own_out = labelled_rollout(env, guide, network_victim(net, kind, source.obs_shape), 0.0,
                                        held_seed + steps // 2, steps // 2, np.random.default_rng(held_seed))
        x_own = torch.as_tensor(own.reshape(len(own), -1), dtype=torch.float32)
        return {"train": measure(net, x, y, names), "heldout_teacher_states": measure(net, x_held, y_held, names),
                "heldout_student_states": measure(net, x_own, targets(own_out, kind), names)}

    _, _, records = dagger_rounds(env, guide, student, source.obs_shape, rounds=rounds, steps=steps, seed=seed,
                                  refit=refit, evaluate=evaluate, kind=kind, beta=beta)
    env.close()
    method = {"name": "dagger-distillation", "teacher": teacher or "the source model", "eps": eps, "kappa": kappa,
              "pgd_steps": pgd_steps, "epochs": epochs, "states": steps, "rounds": rounds, "lr": DAGGER_LR,
              "batch": DAGGER_BATCH, "class_weight_power": DAGGER_WEIGHT_POWER,
              "jitter": DAGGER_JITTER if jittered else 0.0,  # none when the teacher reads the simulator
              "input": "standardized (statistics of round 0's teacher states), folded into the first layer",
              "reference": "Ross et al. 2011 (DAgger); Rusu et al. 2016; Madry et al. 2018"}
    if kind == "continuous":
        method.update(beta=beta, class_weight_power=None,
                      std_floor=DAGGER_STD_FLOOR, **({"ego_jitter": DAGGER_EGO_JITTER} if jittered else {}),
                      init="the source actor's architecture, freshly initialized",
                      loss=continuous_loss)
    last = records[-1]
    summary = ({"clean_agreement": last["train"]["all"], "heldout_agreement": last["heldout_student_states"]["all"]}
               if kind == "discrete" else {"heldout_action_error": last["heldout_student_states"]})
    return _save(out, model, preset, seed, method, folded(student), source.algo, start, (rounds + 1) * steps,
                 {"heldout_seeds": [held_seed, held_seed + steps - 1], **summary, "rounds": records})
