"""Watch saved policies act: one or more --save-model checkpoints, side by side on the same episode start, to a GIF.

    python scripts/watch.py runs/bc_oh/Hopper-v4/seed1.pt runs/c2f/Hopper-v4/seed1.pt --output watch.gif
    python scripts/watch.py runs/c2f/Hopper-v4/seed1.pt --output c2f.gif --seed 7 --max-steps 300 --width 480 --height 360

Each panel is one policy, rebuilt as scripts/evaluate.py rebuilds it, playing the episode that
`scripts/evaluate.py CHECKPOINT --episodes 1 --seed S` plays (the same start and sensor noise, under
the partial observability and control rate its checkpoint records); its method and running return are
written on it, and a panel whose episode has ended holds its last frame. All checkpoints must be of one
env at one frame skip. A frame is drawn every --every steps (default: every 1/25 s of simulated time, so
the GIF plays in real time). Rendering needs OpenGL: the script uses MUJOCO_GL if set, else the first of
egl (a GPU driver) and osmesa (`apt-get install libosmesa6`) that renders here. Needs only pillow
(requirements.txt's matplotlib brings it).
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

sys.path.insert(0, str(Path(__file__).resolve().parent))  # its sibling scripts/evaluate.py
from evaluate import load_policy, positive, read_checkpoint  # noqa: E402  (it puts the repository root on sys.path)
from benchmark.results import OneLineParser, UsageError, run_cli, written_atomically  # noqa: E402

PROBE = "import mujoco; r = mujoco.Renderer(mujoco.MjModel.from_xml_string('<mujoco/>'), 8, 8); r.render(); r.close()"
INSTALL = "install OSMesa (apt-get install libosmesa6) or a GPU driver for EGL"


def renders(backend: str) -> bool:
    """Whether MuJoCo renders a frame with MUJOCO_GL=backend, tried in a fresh interpreter (MuJoCo picks its
    OpenGL library once, when it is imported)."""
    env = {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": "" if backend == "glfw" else backend}
    try:
        return subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, timeout=60).returncode == 0
    except subprocess.TimeoutExpired:
        return False


def find_backend():
    """A MUJOCO_GL value that renders here (MUJOCO_GL's own, if set), or None."""
    if os.environ.get("MUJOCO_GL"):
        return os.environ["MUJOCO_GL"] if renders(os.environ["MUJOCO_GL"]) else None
    candidates = ["egl", "osmesa"] + ["glfw"] * bool(os.environ.get("DISPLAY"))
    return next((backend for backend in candidates if renders(backend)), None)


def use_backend():
    """Set MUJOCO_GL to a backend that renders, before MuJoCo is imported; else one line saying what to install."""
    backend = find_backend()
    if backend is None and os.environ.get("MUJOCO_GL"):
        raise UsageError(f"MuJoCo cannot render with MUJOCO_GL={os.environ['MUJOCO_GL']} here: unset MUJOCO_GL to let the script pick, or {INSTALL}")
    if backend is None:
        raise UsageError(f"no OpenGL backend renders MuJoCo here (tried MUJOCO_GL=egl and osmesa): {INSTALL}")
    os.environ["MUJOCO_GL"] = backend
    if backend in ("egl", "osmesa"):
        os.environ["PYOPENGL_PLATFORM"] = backend


class Panel:
    """One loaded policy on its own env: the episode of evaluate(policy, args, 1, seed), stepped and drawn one step at a time."""

    def __init__(self, loaded: tuple, seed: int, width: int, height: int):
        import mujoco  # only now: MUJOCO_GL is set

        self.module, self.policy, self.args = loaded
        m, args = self.module, self.args
        env = m.make_env(args.env, args.frame_skip)
        self.env = m.PartialObservation(env, m.velocity_dims(env, args.env), args.obs_noise_std, args.hide_velocities, seed)
        self.low, self.high, self.dt = env.action_space.low, env.action_space.high, env.unwrapped.dt
        obs, _ = self.env.reset(seed=seed)  # as evaluate's vector env resets its first env
        self.frames = np.repeat(obs[None], args.history, axis=0)  # [o_{t-H+1}, ..., o_t], the first frame repeated
        self.total, self.steps, self.done = 0.0, 0, False
        model = env.unwrapped.model
        model.vis.global_.offwidth, model.vis.global_.offheight = max(model.vis.global_.offwidth, width), max(model.vis.global_.offheight, height)
        # a smaller shadow map than MuJoCo's 4096^2: half the time of a frame in software OpenGL (OSMesa), no visible change at these sizes
        model.vis.quality.shadowsize = min(model.vis.quality.shadowsize, max(1024, 2 * max(width, height)))
        self.renderer = mujoco.Renderer(model, height, width)
        self.camera = mujoco.MjvCamera()  # the env's own view (gymnasium's default_camera_config), following the body it names
        self.camera.type, self.camera.trackbodyid = mujoco.mjtCamera.mjCAMERA_TRACKING, 1
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
        self.total, self.steps, self.done = self.total + float(reward), self.steps + 1, terminated or truncated
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
    draw, size = ImageDraw.Draw(picture), max(8, image.shape[0] // 16)
    for i, text in enumerate(lines):
        draw.text((4, 2 + i * (size + 3)), text, fill=(255, 255, 255), font=font(size), stroke_width=1, stroke_fill=(0, 0, 0))
    return np.asarray(picture)


def watch(paths: list, output: Path, seed: int, max_steps: int, every, width: int, height: int) -> dict:
    """Load the policies, give each a panel and play them into the GIF `output`; returns what was drawn."""
    loaded = [load_policy(path) for path in paths]  # every refusal before any OpenGL context exists
    panels = []
    try:
        for policy in loaded:
            panels.append(Panel(policy, seed, width, height))
        return play(panels, paths, output, max_steps, every)
    finally:
        for panel in panels:
            panel.close()


def play(panels: list, paths: list, output: Path, max_steps: int, every) -> dict:
    """Step the panels together, draw them side by side every `every` steps into the GIF `output`; returns what was drawn,
    per panel and in all."""
    methods = [panel.module.METHOD for panel in panels]
    names = [method if methods.count(method) == 1 else f"{method} {Path(path).stem}" for method, path in zip(methods, paths)]
    every = every or max(1, round(0.04 / panels[0].dt))  # 1/25 s of simulated time per frame
    last = [(None, -1)] * len(panels)  # per panel (its last picture, its step then): an ended episode's is not drawn again

    def frame():
        for i, panel in enumerate(panels):
            if last[i][1] != panel.steps:
                last[i] = (label(panel.render(), [names[i], f"return {panel.total:.1f}", f"step {panel.steps}" + " (ended)" * panel.done]), panel.steps)
        return Image.fromarray(np.concatenate([image for image, _ in last], axis=1))

    images, step = [frame()], 0
    while step < max_steps and not all(panel.done for panel in panels):
        for panel in panels:
            if not panel.done:
                panel.step()
        step += 1
        if step % every == 0 or step == max_steps or all(panel.done for panel in panels):
            images.append(frame())
    duration = max(20, round(1000 * every * panels[0].dt))  # ms; GIF viewers play faster frames slower
    with written_atomically(output) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=duration, loop=0)
    return {"frames": len(images), "duration": duration, "steps": step,
            "panels": [{"name": name, "return": panel.total, "steps": panel.steps, "ended": panel.done} for name, panel in zip(names, panels)]}


def main(argv=None):
    parser = OneLineParser(prog="python scripts/watch.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoints", nargs="+", help="seed<S>.pt files written by the method files' --save-model, one panel each")
    parser.add_argument("--output", type=Path, default=Path("watch.gif"), help="the animated GIF to write (default watch.gif)")
    parser.add_argument("--seed", type=int, default=0, help="the episode: the one scripts/evaluate.py --seed S --episodes 1 plays")
    parser.add_argument("--max-steps", type=positive, default=1000, help="stop after this many env steps (default 1000, a full episode)")
    parser.add_argument("--every", type=positive, help="draw a frame every N steps (default: every 1/25 s of simulated time)")
    parser.add_argument("--width", type=positive, default=320, help="width of a panel in pixels (default 320)")
    parser.add_argument("--height", type=positive, default=240, help="height of a panel in pixels (default 240)")
    options = parser.parse_args(argv)
    if options.output.suffix.lower() != ".gif":
        raise UsageError(f"--output {options.output} is not a .gif: the script writes animated GIFs, e.g. --output watch.gif")
    settings = {}
    for path in options.checkpoints:
        args = read_checkpoint(path)["args"]
        settings.setdefault((args.get("env"), args.get("frame_skip")), path)
    if len(settings) > 1:
        (env_a, skip_a), (env_b, skip_b) = list(settings)[:2]
        raise UsageError(f"{settings[env_a, skip_a]} is a policy for {env_a} at frame skip {skip_a}, {settings[env_b, skip_b]} for {env_b} at "
                         f"frame skip {skip_b}: panels step together, so watch policies of one env and control rate at a time")
    use_backend()
    start = time.time()
    drawn = watch(options.checkpoints, options.output, options.seed, options.max_steps, options.every, options.width, options.height)
    for panel in drawn["panels"]:
        print(f"{panel['name']}: return {panel['return']!r} over {panel['steps']} steps{' (episode ended)' * panel['ended']}")
    print(f"wrote {options.output}: {drawn['frames']} frames of {len(drawn['panels'])} panel{'s' * (len(drawn['panels']) > 1)} of "
          f"{options.width}x{options.height}, {drawn['duration']} ms each, {drawn['steps']} steps ({os.environ['MUJOCO_GL']}, {time.time() - start:.1f} s)")
    return 0


if __name__ == "__main__":
    run_cli(main)
