"""Pick a VTK render window that works off screen, before pyvista/VTK is imported.

VTK's wheels choose the OpenGL window class at run time from the environment variable
VTK_DEFAULT_OPENGL_WINDOW. EGL works on machines with a GPU and, through Mesa's
surfaceless EGL, on many without one; OSMesa (Debian's libosmesa6) is the software
fallback. Each candidate is tried once in a child process (a failing window can abort the
process); the winner is kept in the environment so child processes skip the probe.
"""

from __future__ import annotations

import os
import subprocess
import sys

CANDIDATES = ("vtkEGLRenderWindow", "vtkOSOpenGLRenderWindow")
_CHOSEN_VAR = "SDFMESH_VTK_WINDOW"

_PROBE = r"""
import pyvista as pv
pv.OFF_SCREEN = True
p = pv.Plotter(off_screen=True, window_size=(64, 48))
p.add_mesh(pv.Sphere(), color="red")
img = p.screenshot(return_img=True)
name = p.ren_win.GetClassName()
p.close()
assert img.std() > 0, "blank image"
print("WINDOW=" + name)
"""


def _works(window: str, timeout: float = 60.0) -> str | None:
    """The render window class VTK really used when asked for `window`, if rendering worked."""
    env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW=window)
    try:
        r = subprocess.run(
            [sys.executable, "-c", _PROBE],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return None
    if r.returncode != 0:
        return None
    for line in r.stdout.splitlines():
        if line.startswith("WINDOW="):
            return line[len("WINDOW="):]
    return None


def choose_window() -> str | None:
    """Return the name of a working off-screen window class (and set the environment)."""
    chosen = os.environ.get(_CHOSEN_VAR)
    if chosen:
        os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = chosen
        return chosen
    preferred = os.environ.get("VTK_DEFAULT_OPENGL_WINDOW")
    order = [preferred] if preferred else []
    order += [c for c in CANDIDATES if c != preferred]
    for window in order:
        used = _works(window)
        if used:
            os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = used
            os.environ[_CHOSEN_VAR] = used
            return used
    return None


_pv = None
_window: str | None = None


def pyvista():
    """Import pyvista set up for off-screen rendering; raises RuntimeError if nothing works."""
    global _pv, _window
    if _pv is None:
        _window = choose_window()
        if _window is None:
            raise RuntimeError(
                "no off-screen VTK render window works here (tried "
                + ", ".join(CANDIDATES)
                + "); install libegl1 libegl-mesa0 or libosmesa6 (tools/setup-python does)"
            )
        import pyvista as pv

        pv.OFF_SCREEN = True
        _pv = pv
    return _pv


def window() -> str | None:
    """The window class chosen so far (None before pyvista() is called)."""
    return _window


if __name__ == "__main__":
    print(choose_window() or "none")
