r"""Watch saved policies act: one or more --save-model checkpoints, side by side on the same
episode start, to a GIF.

    python scripts/watch.py runs/bc_oh_hopper/seed1.pt runs/c2f_hopper/seed1.pt --output watch.gif
    python scripts/watch.py runs/c2f_hopper/seed1.pt --output c2f.gif --seed 7 \
        --max-steps 300 --width 480 --height 360

Each panel is one policy, rebuilt as scripts/evaluate.py rebuilds it, playing the episode that
`scripts/evaluate.py CHECKPOINT --episodes 1 --seed S` plays (the same start and sensor noise,
under the partial observability and control rate its checkpoint records); its method and running
return are written on it, and a panel whose episode has ended holds its last frame. All
checkpoints must be of one env at one frame skip. A frame is drawn every --every steps (default:
every 1/25 s of simulated time, or every step where a step is longer, so the GIF plays in real
time). Rendering needs OpenGL: the script
uses MUJOCO_GL if set, else the first of egl (a GPU driver) and osmesa
(`apt-get install libosmesa6`) that renders here. Needs only pillow (requirements.txt's
matplotlib brings it).
"""

import functools
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch
from PIL import Image, ImageDraw, ImageFont

# Import the sibling scripts/evaluate.py, which puts the repository root on sys.path.
sys.path.insert(0, str(Path(__file__).resolve().parent))
from evaluate import load_policy, non_negative, positive, read_checkpoint
from benchmark.results import OneLineParser, UsageError, run_cli, written_atomically

PROBE = (
    "import mujoco; "
    "r = mujoco.Renderer(mujoco.MjModel.from_xml_string('<mujoco/>'), 8, 8); "
    "r.render(); r.close()"
)
INSTALL = "install OSMesa (apt-get install libosmesa6) or a GPU driver for EGL"
MAX_PIXELS = 4096
"""the widest and tallest panel drawn: a 4K frame, well inside OpenGL's offscreen buffers (Mesa's
EGL and OSMesa refuse sides over 16384) and a GIF's 65535"""
GIF_PIXELS = 65535
"""the widest and tallest frame a GIF holds"""
WHITE = (255, 255, 255)
BLACK = (0, 0, 0)


def renders(backend: str) -> bool:
    """Whether MuJoCo renders a frame with MUJOCO_GL=backend, tried in a fresh interpreter (MuJoCo
    picks its OpenGL library once, when it is imported)."""
    platform = backend
    if backend == "glfw":
        platform = ""
    env = {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": platform}
    command = [sys.executable, "-c", PROBE]
    try:
        probe = subprocess.run(command, env=env, capture_output=True, timeout=60)
    except subprocess.TimeoutExpired:
        return False
    return probe.returncode == 0


def find_backend():
    """A MUJOCO_GL value that renders here (MUJOCO_GL's own, if set), or None."""
    if os.environ.get("MUJOCO_GL"):
        if renders(os.environ["MUJOCO_GL"]):
            return os.environ["MUJOCO_GL"]
        return None
    candidates = ["egl", "osmesa"]
    if os.environ.get("DISPLAY"):
        candidates.append("glfw")
    for backend in candidates:
        if renders(backend):
            return backend
    return None


def use_backend():
    """Set MUJOCO_GL to a backend that renders, before MuJoCo is imported; else one line saying
    what to install."""
    backend = find_backend()
    if backend is None and os.environ.get("MUJOCO_GL"):
        raise UsageError(
            f"MuJoCo cannot render with MUJOCO_GL={os.environ['MUJOCO_GL']} here: "
            f"unset MUJOCO_GL to let the script pick, or {INSTALL}"
        )
    if backend is None:
        raise UsageError(
            f"no OpenGL backend renders MuJoCo here (tried MUJOCO_GL=egl and osmesa): {INSTALL}"
        )
    os.environ["MUJOCO_GL"] = backend
    if backend in ("egl", "osmesa"):
        os.environ["PYOPENGL_PLATFORM"] = backend


class Panel:
    """One loaded policy on its own env: the episode of evaluate(policy, args, 1, seed), stepped
    and drawn one step at a time."""

    def __init__(self, loaded: tuple, seed: int, width: int, height: int):
        # Import MuJoCo only now, when MUJOCO_GL is set.
        import mujoco

        self.module, self.policy, self.args = loaded
        module = self.module
        args = self.args
        env = module.make_env(args.env, args.frame_skip)
        dims = module.velocity_dims(env, args.env)
        self.env = module.PartialObservation(
            env, dims, args.obs_noise_std, args.hide_velocities, seed
        )
        self.low = env.action_space.low
        self.high = env.action_space.high
        self.dt = env.unwrapped.dt
        # Reset as evaluate's vector env resets its first env.
        obs, _ = self.env.reset(seed=seed)
        # The history [o_{t-H+1}, ..., o_t] starts as the first frame repeated.
        self.frames = np.repeat(obs[None], args.history, axis=0)
        self.total = 0.0
        self.steps = 0
        self.done = False
        model = env.unwrapped.model
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, height)
        # A smaller shadow map than MuJoCo's 4096^2 halves the time of a frame in software OpenGL
        # (OSMesa), with no visible change at these sizes.
        shadowsize = max(1024, 2 * max(width, height))
        model.vis.quality.shadowsize = min(model.vis.quality.shadowsize, shadowsize)
        self.renderer = mujoco.Renderer(model, height, width)
        # Use the env's own view (gymnasium's default_camera_config), following the body it names.
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        self.camera.trackbodyid = 1
        for key, value in (env.unwrapped.mujoco_renderer.default_cam_config or {}).items():
            if isinstance(value, np.ndarray):
                getattr(self.camera, key)[:] = value
            else:
                setattr(self.camera, key, value)

    def step(self):
        with torch.no_grad():
            inputs = torch.as_tensor(self.frames.reshape(1, -1), dtype=torch.float32)
            action = self.policy(inputs).numpy()[0].clip(self.low, self.high)
        obs, reward, terminated, truncated, _ = self.env.step(action)
        self.total = self.total + float(reward)
        self.steps = self.steps + 1
        self.done = terminated or truncated
        self.frames = np.concatenate([self.frames[1:], obs[None]])

    def render(self) -> np.ndarray:
        self.renderer.update_scene(self.env.unwrapped.data, camera=self.camera)
        return self.renderer.render()

    def close(self):
        self.renderer.close()
        self.env.close()


@functools.lru_cache
def font(size: int):
    return ImageFont.load_default(size=size)


def label(image: np.ndarray, lines: list):
    """The panel with its lines of text written on it, top left."""
    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    size = max(8, image.shape[0] // 16)
    for i, text in enumerate(lines):
        position = (4, 2 + i * (size + 3))
        draw.text(position, text, fill=WHITE, font=font(size), stroke_width=1, stroke_fill=BLACK)
    return np.asarray(picture)


def watch(
    paths: list, output: Path, seed: int, max_steps: int, every, width: int, height: int
) -> dict:
    """Load the policies, give each a panel and play them into the GIF `output`; returns what was
    drawn."""
    # Every refusal comes before any OpenGL context exists.
    loaded = [load_policy(path) for path in paths]
    if every is not None:
        check_every(loaded[0], every, max_steps)
    panels = []
    try:
        for policy in loaded:
            panels.append(Panel(policy, seed, width, height))
        return play(panels, paths, output, max_steps, every)
    finally:
        for panel in panels:
            panel.close()


def check_every(loaded: tuple, every: int, max_steps: int):
    """Refuse an --every as long as the steps watched (--max-steps, or an episode if shorter):
    it would draw the first and the last frame only (and a frame of 800 s for --every 100000)."""
    module, _, args = loaded
    env = module.make_env(args.env, args.frame_skip)
    length = env.spec.max_episode_steps
    env.close()
    watched = min(length, max_steps)
    limit = f"--max-steps {max_steps}"
    if length < max_steps:
        limit = f"the {length} steps of an episode of {args.env} at frame skip {args.frame_skip}"
    # Frames are drawn at steps 0, every, 2 * every, ... and at the last step watched.
    largest = max(1, watched - 1)
    if every > largest:
        raise UsageError(
            f"--every {every} is not less than {limit}: no frame would be drawn between the first "
            f"and the last; pass --every {largest} or less"
        )


def play(panels: list, paths: list, output: Path, max_steps: int, every) -> dict:
    """Step the panels together, draw them side by side every `every` steps into the GIF
    `output`; returns what was drawn, per panel and in all."""
    methods = [panel.module.METHOD for panel in panels]
    names = []
    for method, path in zip(methods, paths):
        if methods.count(method) == 1:
            names.append(method)
        else:
            names.append(f"{method} {Path(path).stem}")
    # By default, draw a frame every 1/25 s of simulated time (every step where a step is longer).
    every = every or max(1, round(0.04 / panels[0].dt))
    # Keep per panel its last picture and its step then: an ended episode's is not drawn again.
    last = [(None, -1)] * len(panels)

    def frame():
        for i, panel in enumerate(panels):
            if last[i][1] != panel.steps:
                step_text = f"step {panel.steps}"
                if panel.done:
                    step_text += " (ended)"
                lines = [names[i], f"return {panel.total:.1f}", step_text]
                last[i] = (label(panel.render(), lines), panel.steps)
        return Image.fromarray(np.concatenate([image for image, _ in last], axis=1))

    images = [frame()]
    step = 0
    while step < max_steps and not all(panel.done for panel in panels):
        for panel in panels:
            if not panel.done:
                panel.step()
        step += 1
        if step % every == 0 or step == max_steps or all(panel.done for panel in panels):
            images.append(frame())
    # The frame duration in ms: GIF viewers play faster frames slower.
    duration = max(20, round(1000 * every * panels[0].dt))
    with written_atomically(output) as tmp:
        images[0].save(
            tmp, format="GIF", save_all=True, append_images=images[1:], duration=duration, loop=0
        )
    drawn_panels = []
    for name, panel in zip(names, panels):
        drawn_panels.append(
            {"name": name, "return": panel.total, "steps": panel.steps, "ended": panel.done}
        )
    return {"frames": len(images), "duration": duration, "steps": step, "panels": drawn_panels}


def main(argv=None):
    parser = OneLineParser(prog="python scripts/watch.py", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "checkpoints",
        nargs="+",
        help="seed<S>.pt files written by the method files' --save-model, one panel each",
    )
    parser.add_argument(
        "--output",
        type=Path,
        default=Path("watch.gif"),
        help="the animated GIF to write (default watch.gif)",
    )
    parser.add_argument(
        "--seed",
        type=non_negative,
        default=0,
        help="the episode: the one scripts/evaluate.py --seed S --episodes 1 plays",
    )
    parser.add_argument(
        "--max-steps",
        type=positive,
        default=1000,
        help="stop after this many env steps (default 1000, a full episode)",
    )
    parser.add_argument(
        "--every",
        type=positive,
        help="draw a frame every N steps, fewer than the steps watched "
        "(default: every 1/25 s of simulated time, or every step)",
    )
    parser.add_argument(
        "--width",
        type=positive,
        default=320,
        help=f"width of a panel in pixels (default 320, at most {MAX_PIXELS})",
    )
    parser.add_argument(
        "--height",
        type=positive,
        default=240,
        help=f"height of a panel in pixels (default 240, at most {MAX_PIXELS})",
    )
    options = parser.parse_args(argv)
    if options.output.suffix.lower() != ".gif":
        raise UsageError(
            f"--output {options.output} is not a .gif: "
            "the script writes animated GIFs, e.g. --output watch.gif"
        )
    for name in ("width", "height"):
        value = getattr(options, name)
        if value > MAX_PIXELS:
            raise UsageError(
                f"--{name} {value} is more than {MAX_PIXELS} pixels, the largest panel drawn: "
                f"pass --{name} {MAX_PIXELS} or less"
            )
    # The panels stand side by side: the frame is as wide as all of them (as tall as one, at most
    # MAX_PIXELS), and is refused here, before anything is drawn, not when the GIF is saved.
    panels = len(options.checkpoints)
    frame_width = panels * options.width
    if frame_width > GIF_PIXELS:
        largest = GIF_PIXELS // panels
        fix = f"pass --width {largest} or less, or fewer checkpoints"
        if largest == 0:
            fix = f"pass at most {GIF_PIXELS} checkpoints"
        raise UsageError(
            f"{panels} panels of --width {options.width} make a frame {frame_width} pixels wide, "
            f"more than a GIF's {GIF_PIXELS}: {fix}"
        )
    settings = {}
    for path in options.checkpoints:
        args = read_checkpoint(path)["args"]
        # Compared as printed: load_policy refuses a value of the wrong type in one line.
        setting = (str(args.get("env")), str(args.get("frame_skip")))
        settings.setdefault(setting, path)
    if len(settings) > 1:
        (env_a, skip_a), (env_b, skip_b) = list(settings)[:2]
        raise UsageError(
            f"{settings[env_a, skip_a]} is a policy for {env_a} at frame skip {skip_a}, "
            f"{settings[env_b, skip_b]} for {env_b} at frame skip {skip_b}: "
            "panels step together, so watch policies of one env and control rate at a time"
        )
    use_backend()
    start = time.time()
    drawn = watch(
        options.checkpoints,
        options.output,
        options.seed,
        options.max_steps,
        options.every,
        options.width,
        options.height,
    )
    for panel in drawn["panels"]:
        ended = ""
        if panel["ended"]:
            ended = " (episode ended)"
        print(f"{panel['name']}: return {panel['return']!r} over {panel['steps']} steps{ended}")
    count = len(drawn["panels"])
    noun = "panel"
    if count > 1:
        noun = "panels"
    seconds = time.time() - start
    print(
        f"wrote {options.output}: {drawn['frames']} frames of {count} {noun} of "
        f"{options.width}x{options.height}, {drawn['duration']} ms each, "
        f"{drawn['steps']} steps ({os.environ['MUJOCO_GL']}, {seconds:.1f} s)"
    )
    return 0


if __name__ == "__main__":
    run_cli(main)
