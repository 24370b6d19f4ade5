"""Rendered episodes: the simulator's frame beside what the (attacked) policy perceived.

Frames come from highway-env (`render_mode="rgb_array"`); the perception panel draws the
observed vehicles where the policy was told they are (attacked) over where they really
were (clean). Figures are drawn with matplotlib and animations written by its PillowWriter.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from zodrive.attacks.victim import Victim
from zodrive.evaluation.report import headless_pyplot, save_figure
from zodrive.evaluation.rollout import act, left_road

X_RANGE, Y_RANGE = 100.0, 100.0  # [m] the paper's presets' features_range for x and y


@dataclass
class Frame:
    image: np.ndarray          # (H, W, 3) simulator render
    clean: np.ndarray          # (V, F) true observation
    perceived: np.ndarray      # (V, F) what the policy received
    action: Any
    stats: dict[str, Any] = field(default_factory=dict)
    label: str = ""            # the action in words (the scenario's meta-action name, or the values)
    clean_label: str = ""      # attacked: what the policy would have done on the clean observation
    panel: bool = True         # the observation is ego-relative (presence, x, y, ...) rows: draw it
    scale: tuple[float, float] = (X_RANGE, Y_RANGE)  # [m] what a normalized x and y of 1 mean


def record_episode(env, victim: Victim, seed: int, progress: bool = False) -> tuple[list[Frame], dict[str, Any]]:
    """Roll out one episode from `seed`, keeping a frame per decision (env renders rgb_array). Under
    attack each frame also says what the policy would have done on the clean observation: one more
    victim call per step, for the picture only (`display_rows` in the episode's record; the attack's
    queries are counted apart, as always)."""
    from tqdm.auto import tqdm

    obs, info = env.reset(seed=seed)
    frames: list[Frame] = []
    done, total, crashed, terminated, display = False, 0.0, False, False, 0
    bar = tqdm(desc=f"rendering seed {seed}", unit="step", disable=not progress, leave=False)
    while not done:
        clean = info.get("clean_obs")
        action = act(victim, obs, env.action_space)
        clean_label = ""
        if clean is not None:
            clean_label, display = _action_label(env, act(victim, clean, env.action_space)), display + 1
        frames.append(Frame(env.render(), np.asarray(obs if clean is None else clean), np.asarray(obs),
                            action, dict(info.get("attack", {})), _action_label(env, action), clean_label,
                            _relative(env), _scale(env)))
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        crashed = bool(info.get("crashed", False))
        done = terminated or truncated
        bar.update()
    bar.close()
    last = frames[-1]  # the state the episode ended in, with the last step's perception and attack note
    frames.append(Frame(env.render(), last.clean, last.perceived, last.action, last.stats, last.label,
                        last.clean_label, last.panel, last.scale))
    return frames, {"seed": seed, "return": total, "length": len(frames) - 1, "crashed": crashed,
                    "offroad": left_road(env, terminated, crashed), "display_rows": display}


def _relative(env) -> bool:
    """Whether observations are rows of (presence, x, y, ...) relative to the ego (drawable)."""
    observer = getattr(env.unwrapped, "observation_type", None)
    features = list(getattr(observer, "features", []))[:3]
    return features == ["presence", "x", "y"] and not getattr(observer, "absolute", True)


def _scale(env) -> tuple[float, float]:
    """The metres behind a normalized x and y of 1: the observer's `features_range` (highway-env
    fills in its own default, from the road, at the first observation)."""
    ranges = getattr(getattr(env.unwrapped, "observation_type", None), "features_range", None) or {}
    x, y = ranges.get("x", (-X_RANGE, X_RANGE)), ranges.get("y", (-Y_RANGE, Y_RANGE))
    return float(max(abs(x[0]), abs(x[1]))), float(max(abs(y[0]), abs(y[1])))


def _action_label(env, action: Any) -> str:
    """The action in words: the scenario's meta-action name, or each continuous dimension."""
    action_type = getattr(env.unwrapped, "action_type", None)
    if isinstance(action, (int, np.integer)):
        names = getattr(action_type, "actions", None)
        return str(names[int(action)]) if names else f"action {int(action)}"
    values = np.asarray(action, dtype=float).ravel()
    if action_type is not None and hasattr(action_type, "lateral"):
        dims = [d for d, on in (("accel", action_type.longitudinal), ("steer", action_type.lateral)) if on]
    else:
        dims = [f"a{i}" for i in range(len(values))]
    return " ".join(f"{d} {v:+.2f}" for d, v in zip(dims, values))


def draw(frame: Frame, fig, step: int, title: str = "",
         extent: tuple[tuple[float, float], float] | None = None) -> None:
    """Draw one frame on `fig`: simulator left, perception right, in the fixed layout and axis
    `extent` of the whole episode (`episode_extent`), so that nothing jumps between frames."""
    fig.clear()
    if frame.panel:
        left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [2.2, 1]})
        fig.subplots_adjust(left=0.01, right=0.97, bottom=0.2, top=0.86, wspace=0.22)  # room for the x label
    else:  # no ego-relative vehicles to draw: the simulator's image alone
        left, right = fig.subplots(1, 1), None
    left.imshow(frame.image)
    left.set_axis_off()
    said = f"{title}step {step}: {frame.label}"
    if frame.clean_label:
        said += f"  (on the clean observation: {frame.clean_label})"
    left.set_title(said, fontsize=9)
    if right is None:
        return
    for i, (real, seen) in enumerate(zip(frame.clean, frame.perceived)):
        if i == 0:
            continue
        points = []
        for row, style, label in ((real, dict(facecolor="tab:green", alpha=0.5), "real"),
                                  (seen, dict(facecolor="none", edgecolor="tab:red", lw=1.5, zorder=3), "perceived")):
            if row[0] > 0:
                points.append((row[1] * frame.scale[0], row[2] * frame.scale[1]))
                right.add_patch(_car(*points[-1], **style, label=label if i == 1 else None))
        if len(points) == 2 and points[0] != points[1]:  # each perceived box tied to its real car
            right.plot(*zip(*points), color="tab:red", lw=0.8, ls=":", zorder=2)
    right.add_patch(_car(0.0, 0.0, facecolor="tab:blue", label="ego"))
    (x_low, x_high), y_half = extent or panel_extent(frame)
    right.set_xlim(x_low, x_high)
    right.set_ylim(y_half, -y_half)  # right lanes down, as in the simulator's image
    right.set_xlabel("longitudinal x [m] (ego frame)")
    right.set_ylabel("lateral y [m]")
    right.set_title("observation", fontsize=9)
    right.legend(loc="best", fontsize=7)
    if frame.stats:
        right.text(0.02, 0.98, f"Linf {frame.stats.get('linf', 0):.3f}\nqueries {frame.stats.get('queries', 0)}",
                   transform=right.transAxes, va="top", fontsize=7)


def panel_extent(frame: Frame) -> tuple[tuple[float, float], float]:
    """Axis limits of the perception panel: the four lanes at least, and every vehicle drawn,
    real or perceived (an attack may move a vehicle 20 m sideways)."""
    rows = [row for obs in (frame.clean, frame.perceived) for i, row in enumerate(obs) if i > 0 and row[0] > 0]
    xs = [row[1] * frame.scale[0] for row in rows] or [0.0]
    ys = [abs(row[2] * frame.scale[1]) for row in rows] or [0.0]
    return (min(-30.0, min(xs) - 5.0), max(90.0, max(xs) + 5.0)), max(14.0, max(ys) + 3.0)


def _car(x: float, y: float, /, **style: Any) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((x - 2.5, y - 1.0), 5.0, 2.0, **style)  # a 5 m x 2 m car


def episode_extent(frames: list[Frame]) -> tuple[tuple[float, float], float]:
    """One perception-panel extent for a whole episode: every frame's vehicles fit."""
    extents = [panel_extent(f) for f in frames]
    return (min(e[0][0] for e in extents), max(e[0][1] for e in extents)), max(e[1] for e in extents)


def save_png(frames: list[Frame], path: Path, *, title: str = "", index: int = -1) -> None:
    fig = headless_pyplot().figure(figsize=(12, 3.2), dpi=110)
    draw(frames[index], fig, index % len(frames), title)
    save_figure(fig, path, dpi="figure")


def save_mp4(frames: list[Frame], path: Path, *, title: str = "") -> bool:
    """Every decision as an MP4 at 15 fps (real time), through imageio-ffmpeg's ffmpeg binary
    (optional extra `zodrive[video]`); False when that is not installed."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return False
    plt = headless_pyplot()
    from matplotlib.animation import FFMpegWriter, FuncAnimation

    plt.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
    fig = plt.figure(figsize=(10, 2.8), dpi=80)
    extent = episode_extent(frames)
    anim = FuncAnimation(fig, lambda i: draw(frames[i], fig, i, title, extent), frames=len(frames))
    path.parent.mkdir(parents=True, exist_ok=True)
    anim.save(path, writer=FFMpegWriter(fps=15, codec="libx264", extra_args=["-pix_fmt", "yuv420p"]))
    plt.close(fig)
    return True


def save_gif(frames: list[Frame], path: Path, *, title: str = "", every: int = 1, last: int = 150) -> None:
    """An animated GIF of the last `last` decisions (every `every`-th: all by default), ending on the crash."""
    plt = headless_pyplot()
    from matplotlib.animation import FuncAnimation, PillowWriter

    start = max(0, len(frames) - last)
    picks = list(range(start, len(frames), every))
    if picks[-1] != len(frames) - 1:
        picks.append(len(frames) - 1)
    fig = plt.figure(figsize=(10, 2.8), dpi=80)
    extent = episode_extent([frames[i] for i in picks])
    anim = FuncAnimation(fig, lambda i: draw(frames[i], fig, i, title, extent), frames=picks)
    path.parent.mkdir(parents=True, exist_ok=True)
    anim.save(path, writer=PillowWriter(fps=5))
    plt.close(fig)
