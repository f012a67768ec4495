"""Both off-screen backends (EGL, OSMesa) render the same frames; a missing one fails clearly; exits are clean.

Each backend is chosen when MuJoCo is first imported, so every case runs in
its own Python process.
"""

import ctypes.util
import os
import subprocess
import sys

import numpy as np
import pytest

HAS_OSMESA = ctypes.util.find_library("OSMesa") is not None
HAS_EGL = ctypes.util.find_library("EGL") is not None

#: Renders fixed poses of the first training house and saves segmentation and depth.
RENDER = """
import sys, numpy as np, leaps_mj
from leaps_mj.environment.roomnav import EpisodeSpec
env = leaps_mj.load(sys.argv[1], "train", width=64, height=48, horizon=50)
spec = env.sample_episode()
ts = env.reset_to(spec)
seg, depth = [ts.observation["segmentation"]], [ts.observation["depth"]]
for action in (0, 3, 0, 4, 4, 1, 0, 2):
    ts = env.step(action)
    seg.append(ts.observation["segmentation"]); depth.append(ts.observation["depth"])
np.savez(sys.argv[2], seg=np.stack(seg), depth=np.stack(depth))
env.close()
import os; print(os.environ["MUJOCO_GL"])
"""

#: Hides a library from ctypes (as on a machine without it), then runs the rest of the script.
HIDE = """
import ctypes.util
_find = ctypes.util.find_library
ctypes.util.find_library = lambda name: None if name in {hidden!r} else _find(name)
"""


def _run(code: str, env_vars: dict, *args) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM",
                                                          "LEAPS_MJ_GL_PROBLEM")}
    env.update(env_vars)
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.skipif(not (HAS_OSMESA and HAS_EGL), reason="needs libEGL and libOSMesa (apt-get install libosmesa6)")
def test_egl_and_osmesa_render_the_same_frames(tiny_dataset, tmp_path):
    frames = {}
    for backend in ("egl", "osmesa"):
        out = tmp_path / f"{backend}.npz"
        done = _run(RENDER, {"MUJOCO_GL": backend}, tiny_dataset, out)
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip().endswith(backend)
        frames[backend] = np.load(out)
    np.testing.assert_array_equal(frames["egl"]["seg"], frames["osmesa"]["seg"])
    np.testing.assert_allclose(frames["egl"]["depth"], frames["osmesa"]["depth"], atol=1e-4)
    assert len(np.unique(frames["egl"]["seg"])) > 3  # the frames show a room, not a blank


@pytest.mark.skipif(not HAS_OSMESA, reason="needs libOSMesa (apt-get install libosmesa6)")
def test_unset_backend_falls_back_to_osmesa_when_egl_is_missing(tiny_dataset, tmp_path):
    done = _run(HIDE.format(hidden={"EGL"}) + RENDER, {}, tiny_dataset, tmp_path / "frames.npz")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().endswith("osmesa")


@pytest.mark.parametrize("hidden, setting, expected", [
    ({"OSMesa"}, {"MUJOCO_GL": "osmesa"}, "MUJOCO_GL='osmesa' needs libOSMesa, which is not installed "
                                          "(Debian: apt-get install libosmesa6)"),
    ({"EGL", "OSMesa"}, {}, "no off-screen OpenGL backend"),
])
def test_a_missing_backend_is_one_clear_error(tiny_dataset, hidden, setting, expected):
    code = HIDE.format(hidden=hidden) + """
import sys, leaps_mj
from leaps_mj.world import generator
generator.generate(3, "h")  # what does not draw still works
try:
    leaps_mj.load(sys.argv[1], "train")
except RuntimeError as e:
    print(type(e).__name__, e)
"""
    done = _run(code, setting, tiny_dataset)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("RenderError") and expected in done.stdout
    assert "libosmesa6" in done.stdout


@pytest.mark.parametrize("backend", ["egl", pytest.param("osmesa", marks=pytest.mark.skipif(
    not HAS_OSMESA, reason="needs libOSMesa"))])
def test_environments_left_open_exit_without_a_traceback(tiny_dataset, backend):
    code = """
import sys, leaps_mj
def main():
    env = leaps_mj.load(sys.argv[1], "train", width=32, height=24)
    env.reset()
    loop = {"env": env}
    loop["self"] = loop  # a reference cycle: freed only by the collection at interpreter exit
main()
print("done")
"""
    done = _run(code, {"MUJOCO_GL": backend}, tiny_dataset)
    assert done.returncode == 0 and done.stdout.strip() == "done", done.stderr
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr


def test_progress_bars_stay_quiet_without_a_terminal(tiny_dataset, tmp_path):
    done = _run("import sys, runpy; sys.argv = sys.argv[1:]; runpy.run_module('leaps_mj.evaluate', run_name='__main__')",
                {}, "evaluate", "--agent", "random", "--dataset", tiny_dataset, "--split", "test", "--horizon", "50",
                "--out", tmp_path / "eval")
    assert done.returncode == 0, done.stderr
    updates = [line for line in done.stderr.replace("\r", "\n").splitlines() if "episodes" in line]
    assert 1 <= len(updates) <= 4, updates  # the bar's first and last states, not one line per episode
