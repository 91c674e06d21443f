"""Rollout video: MuJoCo's offscreen renderer (EGL or OSMesa, no display) with the ToF rays drawn.

The terrain is coloured by height (foottof.terrain.preview.height_rgb: pits dark, tops light) by
a 2D texture over the heightfield. The physics model carries no texture (MJX keeps texture data
as hashed static metadata): the render context is made from a model of the terrain alone with
that texture, and the terrain's scene geom is pointed at it each frame.

The GL context is made here, not by ``mujoco.Renderer``, because MuJoCo picks its backend from
``MUJOCO_GL`` when ``mujoco`` is first imported (long before a video is asked for). Backends are
tried in the order ``MUJOCO_GL`` (if it names one of ``BACKENDS``), EGL, OSMesa, skipping those
whose library is not installed; ``.ci/render-deps.sh`` installs Mesa's EGL and OSMesa.
"""

from __future__ import annotations

import copy
import ctypes.util
import os
import subprocess
from fractions import Fraction

import numpy as np

BACKENDS = {"egl": "EGL", "osmesa": "OSMesa"}  # MUJOCO_GL name -> shared library it needs
FORMATS = ("mp4", "gif")
RAY_HIT_RGBA = (0.1, 0.95, 0.25, 0.9)  # a ray that hit the terrain within range
RAY_MISS_RGBA = (0.95, 0.3, 0.2, 0.35)  # a ray without a return within max range (drawn to it)
HIT_POINT_RADIUS_M = 0.008
TERRAIN_RGBA = (0.62, 0.58, 0.52, 1.0)  # a terrain that is not a heightfield (a plane)
TEXELS_PER_CELL = 2  # height texture resolution (see _texels)
# Unlit share of the terrain's height colour: from the video's low camera the headlight lights the
# walls facing it more than the tops, which without it looked darker than the walls under them.
TERRAIN_EMISSION = 0.4


def available_backends() -> list[str]:
    """Headless GL backends whose shared library is installed, in the order they are tried."""
    want = os.environ.get("MUJOCO_GL", "").lower().strip()
    order = ([want] if want in BACKENDS else []) + [b for b in BACKENDS if b != want]
    return [b for b in order if ctypes.util.find_library(BACKENDS[b])]


def _texels(rgb: np.ndarray) -> np.ndarray:
    """uint8 texels (k (n - 1), k (m - 1), 3), k = TEXELS_PER_CELL, of vertex colours rgb (n, m, 3)
    in [0, 1]: each texel the bilinear blend of the vertex colours at its centre.

    MuJoCo stretches a texture over the hfield's vertex span, so with one texel per vertex the
    texel centres drift off the vertices by up to half a cell toward the edges and a 1 m wall
    between two vertices would take one blurred colour; sampled at the texel centres the GPU's
    linear filter redraws the vertex colours' ramp down each wall instead.
    """
    for axis in (0, 1):
        n = rgb.shape[axis]
        u = (np.arange(TEXELS_PER_CELL * (n - 1)) + 0.5) / TEXELS_PER_CELL  # in vertex units
        i = np.floor(u).astype(int)  # <= n - 2
        shape = [1, 1, 1]
        shape[axis] = -1
        f = (u - i).astype(np.float32).reshape(shape)  # weight of vertex i + 1
        lo, hi = np.take(rgb, i, axis=axis), np.take(rgb, i + 1, axis=axis)
        rgb = lo + (hi - lo) * f
    return np.round(255 * rgb).astype(np.uint8)


def height_texture_model(m, terrain: int):
    """A model of the heightfield geom ``terrain`` of ``m`` alone, with its material's 2D texture
    coloured by the vertices' heights (:func:`_texels`; texture row 0 is the hfield's +y edge,
    as MuJoCo maps it).

    Args:
      m: a compiled ``mujoco.MjModel`` whose geom ``terrain`` is an hfield geom.
      terrain: that geom's id.

    Returns:
      The ``mujoco.MjModel`` (hfield 0, texture 0, material 0, geom 0), its offscreen buffer and
      statistics (which size the context's framebuffer, fog and shadows) copied from ``m``.
    """
    import mujoco

    from foottof.terrain.preview import height_rgb

    hid = int(m.geom_dataid[terrain])
    nrow, ncol = int(m.hfield_nrow[hid]), int(m.hfield_ncol[hid])
    size = m.hfield_size[hid]
    adr = int(m.hfield_adr[hid])
    data = np.asarray(m.hfield_data[adr : adr + nrow * ncol]).reshape(nrow, ncol)
    z_m = m.geom_pos[terrain][2] + data * size[2]  # world heights of the vertices (geom unrotated)
    h, w = TEXELS_PER_CELL * (nrow - 1), TEXELS_PER_CELL * (ncol - 1)
    xml = f"""<mujoco><asset>
      <hfield name="terrain" nrow="{nrow}" ncol="{ncol}" size="{" ".join(map(str, size))}"/>
      <texture name="height" type="2d" builtin="flat" width="{w}" height="{h}" rgb1="1 1 1"/>
      <material name="height" texture="height" texuniform="false" texrepeat="1 1"/>
    </asset><worldbody><geom type="hfield" hfield="terrain" material="height"/></worldbody></mujoco>"""
    mt = mujoco.MjModel.from_xml_string(xml)
    mt.hfield_data[:] = data.ravel()
    mt.tex_data[:] = _texels(height_rgb(z_m).astype(np.float32)[::-1]).ravel()
    mt.vis.global_.offwidth = m.vis.global_.offwidth
    mt.vis.global_.offheight = m.vis.global_.offheight
    mt.vis.quality.shadowsize = m.vis.quality.shadowsize
    mt.stat.extent = m.stat.extent
    mt.stat.center[:] = m.stat.center
    return mt


def _gl_context(width: int, height: int):
    errors = []
    for name in available_backends():
        try:
            if name == "egl":
                from mujoco.egl import GLContext
            else:
                from mujoco.osmesa import GLContext
            ctx = GLContext(width, height)
            ctx.make_current()
            return ctx
        except Exception as e:  # noqa: BLE001 - every failure is reported below
            errors.append(f"{name}: {type(e).__name__}: {e}")
    tried = (
        "; ".join(errors) if errors else f"none of the libraries {list(BACKENDS.values())} found"
    )
    raise RuntimeError(
        f"no headless OpenGL for MuJoCo's offscreen renderer ({tried}). Install Mesa's EGL or "
        "OSMesa (`make render-deps`, i.e. `bash .ci/render-deps.sh`) and retry."
    )


class RolloutRenderer:
    """Renders physics states of one model with line segments (the ToF rays) added.

    Args:
      m: the ``mujoco.MjModel`` (a copy is made; its offscreen buffer is resized to fit).
      width, height: frame size [px].
      distance_m, azimuth_deg, elevation_deg: the free camera, which follows the base.
    """

    def __init__(
        self,
        m,
        width: int = 640,
        height: int = 480,
        distance_m: float = 2.6,
        azimuth_deg: float = 130.0,
        elevation_deg: float = -22.0,
    ):
        import mujoco

        if width < 16 or height < 16:
            raise ValueError(f"frame size {width}x{height}: both sides must be >= 16 px")
        self._mj = mujoco
        self.m = copy.deepcopy(m)
        self.m.vis.global_.offwidth = max(int(self.m.vis.global_.offwidth), width)
        self.m.vis.global_.offheight = max(int(self.m.vis.global_.offheight), height)
        self.m.vis.headlight.ambient[:] = 0.35
        self.m.vis.headlight.diffuse[:] = 0.6
        terrain = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_GEOM, "terrain")
        self._textured = terrain >= 0 and self.m.geom_type[terrain] == mujoco.mjtGeom.mjGEOM_HFIELD
        self._terrain = terrain
        if terrain >= 0 and not self._textured:
            self.m.geom_rgba[terrain] = TERRAIN_RGBA
        # The context (what the GPU holds: hfield, textures; the robot is primitives only) comes
        # from the textured terrain model when there is one.
        con_model = height_texture_model(self.m, terrain) if self._textured else self.m
        self.d = mujoco.MjData(self.m)
        self.width, self.height = width, height
        self._ctx = _gl_context(self.m.vis.global_.offwidth, self.m.vis.global_.offheight)
        self.scene = mujoco.MjvScene(self.m, maxgeom=self.m.ngeom + 4000)
        try:
            self._con = mujoco.MjrContext(con_model, mujoco.mjtFontScale.mjFONTSCALE_100)
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)
        except Exception:
            self._ctx.free()
            raise
        self._opt = mujoco.MjvOption()
        self._pert = mujoco.MjvPerturb()
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.distance = distance_m
        self.camera.azimuth = azimuth_deg
        self.camera.elevation = elevation_deg
        self._rect = mujoco.MjrRect(0, 0, width, height)

    def close(self) -> None:
        if self._ctx is not None:
            self._con.free()
            self._ctx.free()
            self._ctx = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _texture_terrain(self) -> None:
        """Points the terrain's scene geom at the context's height texture (material 0)."""
        for g in self.scene.geoms[: self.scene.ngeom]:
            if g.objtype == self._mj.mjtObj.mjOBJ_GEOM and g.objid == self._terrain:
                g.matid = 0
                g.rgba[:] = 1.0  # the texture's colours unmodulated
                g.emission = TERRAIN_EMISSION
                if hasattr(g, "texid"):  # a scene geom that names its own texture (MuJoCo 4)
                    g.texid = 0
                    g.texrepeat[:] = 1.0
                    g.texuniform = 0
                return

    def _next_geom(self):
        scn = self.scene
        if scn.ngeom >= scn.maxgeom:
            raise RuntimeError(f"scene full ({scn.maxgeom} geoms): too many rays to draw")
        scn.ngeom += 1
        return scn.geoms[scn.ngeom - 1]

    def _add_segment(self, a, b, rgba) -> None:
        mj, g = self._mj, self._next_geom()
        mj.mjv_initGeom(
            g,
            mj.mjtGeom.mjGEOM_LINE,
            np.zeros(3),
            np.zeros(3),
            np.eye(3).ravel(),
            np.asarray(rgba, np.float32),
        )
        mj.mjv_connector(
            g, mj.mjtGeom.mjGEOM_LINE, 2.0, np.asarray(a, np.float64), np.asarray(b, np.float64)
        )

    def _add_point(self, p, rgba) -> None:
        mj = self._mj
        mj.mjv_initGeom(
            self._next_geom(),
            mj.mjtGeom.mjGEOM_SPHERE,
            np.full(3, HIT_POINT_RADIUS_M),
            np.asarray(p, np.float64),
            np.eye(3).ravel(),
            np.asarray(rgba, np.float32),
        )

    def render(self, qpos, origins=None, ends=None, hit=None) -> np.ndarray:
        """One frame (height, width, 3) uint8 of the state ``qpos`` (nq,).

        Args:
          qpos: physics state; the camera looks at the base (qpos[0:3]).
          origins: optional (F, 3) ray origins [m]; with ``ends`` (F, R, 3) and ``hit`` (F, R)
            (foottof.eval.analysis.ray_segments at one step) the rays are drawn, hits green with
            a dot at the hit point, rays without a return red up to max range.
        """
        mj = self._mj
        if self._ctx is None:
            raise RuntimeError("renderer is closed")
        self.d.qpos[:] = qpos
        mj.mj_kinematics(self.m, self.d)
        self.camera.lookat[:] = self.d.qpos[0:3]
        mj.mjv_updateScene(
            self.m, self.d, self._opt, self._pert, self.camera, mj.mjtCatBit.mjCAT_ALL, self.scene
        )
        if self._textured:
            self._texture_terrain()
        if origins is not None:
            for f in range(len(origins)):
                for r in range(ends.shape[1]):
                    rgba = RAY_HIT_RGBA if hit[f, r] else RAY_MISS_RGBA
                    self._add_segment(origins[f], ends[f, r], rgba)
                    if hit[f, r]:
                        self._add_point(ends[f, r], RAY_HIT_RGBA)
        mj.mjr_render(self._rect, self.scene, self._con)
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        mj.mjr_readPixels(rgb, None, self._rect, self._con)
        return np.flipud(rgb)


def render_rollout(
    m,
    qpos,
    rays: dict | None = None,
    stride: int = 1,
    width: int = 640,
    height: int = 480,
    progress=None,
) -> np.ndarray:
    """Frames (N, height, width, 3) uint8 of every ``stride``-th state of ``qpos`` (T, nq).

    Args:
      m: the env's ``mujoco.MjModel`` (``env.mj_model``).
      qpos: (T, nq) physics states.
      rays: optional foottof.eval.analysis.ray_segments output for the same T steps.
      stride: render every stride-th step (>= 1).
      progress: optional tqdm bar, advanced once per frame.
    """
    qpos = np.asarray(qpos)
    if stride < 1:
        raise ValueError(f"stride={stride}: must be >= 1")
    if qpos.ndim != 2 or qpos.shape[1] != m.nq:
        raise ValueError(f"qpos has shape {qpos.shape}; expected (T, {m.nq})")
    frames = []
    with RolloutRenderer(m, width, height) as r:
        for t in range(0, len(qpos), stride):
            if rays is None:
                frames.append(r.render(qpos[t]))
            else:
                frames.append(
                    r.render(qpos[t], rays["origins"][t], rays["ends"][t], rays["hit"][t])
                )
            if progress is not None:
                progress.update(1)
    return np.stack(frames)


def write_video(path: str, frames: np.ndarray, fps: float) -> str:
    """Writes frames (N, H, W, 3) uint8 to ``path`` (.mp4 with H.264 or .gif) atomically.

    Returns:
      ``path``.

    Raises:
      ValueError: unknown extension, bad fps or frames.
    """
    import imageio.v2 as imageio

    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if ext not in FORMATS:
        raise ValueError(f"video path {path!r}: extension must be one of {list(FORMATS)}")
    if not fps > 0:
        raise ValueError(f"fps={fps}: must be > 0")
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8 or not len(frames):
        raise ValueError(f"frames {frames.shape} {frames.dtype}: expected (N>0, H, W, 3) uint8")
    if ext == "mp4" and (frames.shape[1] % 2 or frames.shape[2] % 2):
        raise ValueError(f"frame size {frames.shape[2]}x{frames.shape[1]}: H.264 needs even sides")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = f"{path[: -len(ext) - 1]}.partial.{ext}"
    try:
        if ext == "mp4":
            _write_mp4(tmp, frames, fps)
        else:
            imageio.mimsave(tmp, list(frames), duration=1000.0 / fps, loop=0)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def _write_mp4(path: str, frames: np.ndarray, fps: float) -> None:
    """Pipes frames (N, H, W, 3) uint8 into imageio-ffmpeg's ffmpeg: H.264, CRF 15, yuv420p.

    The command is the one ``imageio.get_writer(codec="libx264", quality=7, macro_block_size=1)``
    runs (the same bytes out), but started with ``process_group=0`` instead of its
    ``preexec_fn=os.setpgrp``: a preexec_fn makes Python fork the interpreter, which JAX warns
    "os.fork() was called ... deadlock" about; without one the child is vfork'ed and exec'ed at
    once, in its own process group still (so Ctrl-C reaches Python, which closes the pipe).
    """
    import imageio_ffmpeg

    _, h, w, _ = frames.shape
    cmd = [
        imageio_ffmpeg.get_ffmpeg_exe(),
        "-y",
        *("-f", "rawvideo", "-vcodec", "rawvideo", "-s", f"{w}x{h}", "-pix_fmt", "rgb24"),
        *("-r", str(Fraction(fps).limit_denominator()), "-i", "-", "-an"),
        *("-vcodec", "libx264", "-pix_fmt", "yuv420p", "-crf", "15", "-v", "error", path),
    ]
    with subprocess.Popen(
        cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, process_group=0
    ) as p:  # on exit: closes stdin (ffmpeg finishes the file) and waits
        try:
            for f in frames:
                p.stdin.write(np.ascontiguousarray(f).tobytes())
        except BrokenPipeError:
            pass  # ffmpeg stopped early; its exit status below says so
    if p.returncode:
        raise RuntimeError(f"ffmpeg exited with status {p.returncode} writing {path!r}")
