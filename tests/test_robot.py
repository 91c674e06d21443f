"""Tests of foottof.robot against MuJoCo C (mj_kinematics, collisions) and hand-computed values."""

import math

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from configs import _env
from foottof import constants
from foottof.physics.mjx_backend import control_step
from foottof.robot import (
    DEFAULT_TUNING,
    default_qpos,
    forward_kinematics,
    make_model,
    nominal_base_height,
    pd_torque,
    world_foot_kinematics,
)
from foottof.robot import kinematics as kin
from foottof.robot import model as model_lib
from foottof.terrain.heightfield import Heightfield

FOOT_R = constants.FOOT_RADIUS_M


def _ids(m, objtype, names):
    return np.array([mujoco.mj_name2id(m, objtype, n) for n in names])


def _full_inertia(m, body_id):
    """Inertia tensor about the COM in the body frame, rebuilt from MuJoCo's principal form."""
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, m.body_iquat[body_id])
    r = r.reshape(3, 3)
    return r @ np.diag(m.body_inertia[body_id]) @ r.T


@pytest.fixture(scope="module")
def m_plane():
    return make_model()


# --------------------------------------------------------------------------------------------
# Model structure, masses, mirroring.


def test_names_and_ordering(m_plane):
    m = m_plane
    assert (m.nq, m.nv, m.nu) == (19, 18, 12)
    jid = _ids(m, mujoco.mjtObj.mjOBJ_JOINT, constants.JOINT_NAMES)
    assert (jid >= 0).all()
    np.testing.assert_array_equal(m.jnt_qposadr[jid], np.arange(7, 19))
    np.testing.assert_array_equal(m.jnt_dofadr[jid], np.arange(6, 18))
    assert m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert m.body(m.jnt_bodyid[0]).name == constants.BASE_BODY
    # actuator i drives joint i, torque limits +-80 N m
    aid = _ids(m, mujoco.mjtObj.mjOBJ_ACTUATOR, constants.JOINT_NAMES)
    np.testing.assert_array_equal(aid, np.arange(12))
    np.testing.assert_array_equal(m.actuator_trnid[:, 0], jid)
    np.testing.assert_allclose(m.actuator_ctrlrange, [[-80.0, 80.0]] * 12)
    np.testing.assert_allclose(m.actuator_gear[:, 0], 1.0)
    assert (_ids(m, mujoco.mjtObj.mjOBJ_GEOM, constants.FOOT_GEOMS) >= 0).all()
    assert (_ids(m, mujoco.mjtObj.mjOBJ_SITE, constants.TOF_SITES) >= 0).all()
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "terrain") >= 0
    assert m.opt.timestep == constants.PHYSICS_DT_S
    # only spheres collide (MJX hfield cost): every collidable robot geom is a sphere
    robot = m.geom_bodyid > 0
    collide = (m.geom_contype | m.geom_conaffinity) > 0
    assert (m.geom_type[robot & collide] == mujoco.mjtGeom.mjGEOM_SPHERE).all()
    names = {m.geom(i).name for i in np.flatnonzero(robot & collide)}
    expected = set(constants.FOOT_GEOMS) | {f"{leg}_knee" for leg in constants.FEET}
    assert expected <= names and all(n in expected or n.startswith("base_") for n in names)


def test_total_mass(m_plane):
    # 26.3631 + 4 * (0.36586 + 5.13220 + 0.79598) = 51.53926 kg (ANYmal-D URDF, ANYbotics/anymal_d_simple_description, links lumped, no payload)
    assert float(np.sum(m_plane.body_mass)) == pytest.approx(51.53926, abs=1e-6)
    assert mujoco.mj_getTotalmass(m_plane) == pytest.approx(51.539, abs=1e-3)


def test_inertials_mirror_lf(m_plane):
    """Each leg's COM and full inertia tensor equal LF's reflected by S = diag(sx, sy, 1)."""
    m = m_plane
    for part in ("hip", "thigh", "shank"):
        lf = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"LF_{part}")
        ixx, iyy, izz, ixy, ixz, iyz = model_lib.LEG_INERTIALS[part][2]
        lf_tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        np.testing.assert_allclose(_full_inertia(m, lf), lf_tensor, atol=1e-9)
        for leg in constants.FEET:
            b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{leg}_{part}")
            s = np.diag([*kin.leg_signs(leg), 1.0])
            np.testing.assert_allclose(m.body_ipos[b], s @ m.body_ipos[lf], atol=1e-12)
            np.testing.assert_allclose(_full_inertia(m, b), s @ lf_tensor @ s, atol=1e-9)
            np.testing.assert_allclose(m.body_mass[b], m.body_mass[lf])


def test_haa_ranges_mirror(m_plane):
    m = m_plane
    rng = {leg: m.jnt_range[m.joint(f"{leg}_HAA").id] for leg in constants.FEET}
    np.testing.assert_allclose(rng["LF"], [-0.7854, 0.6109])
    np.testing.assert_allclose(rng["LH"], [-0.7854, 0.6109])
    np.testing.assert_allclose(rng["RF"], [-0.6109, 0.7854])
    np.testing.assert_allclose(rng["RH"], [-0.6109, 0.7854])
    for j in ("HFE", "KFE"):
        np.testing.assert_allclose(m.jnt_range[m.joint(f"LF_{j}").id], [-9.4248, 9.4248])


def test_no_self_collision_only_terrain(m_plane):
    """Random (often self-intersecting) poses high above the ground: MuJoCo finds no contact.
    Low above the ground: every contact is robot-vs-terrain."""
    m = m_plane
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    terrain = m.geom("terrain").id
    for _ in range(200):
        d.qpos[:] = default_qpos(base_height=3.0)
        d.qpos[7:] = rng.uniform(-math.pi, math.pi, 12)
        mujoco.mj_forward(m, d)
        assert d.ncon == 0
    hits = 0
    for _ in range(200):
        d.qpos[:] = default_qpos(base_height=rng.uniform(0.05, 0.4))
        d.qpos[7:] = rng.uniform(-math.pi, math.pi, 12)
        mujoco.mj_forward(m, d)
        for c in d.contact[: d.ncon]:
            assert terrain in (c.geom1, c.geom2)
        hits += d.ncon
    assert hits > 0


# --------------------------------------------------------------------------------------------
# Forward kinematics vs mj_kinematics.


@pytest.mark.parametrize("shank_scale", [0.8, 1.0, 1.2])
def test_fk_matches_mj_kinematics(shank_scale):
    tilt = 15.0
    m = make_model(shank_scale=shank_scale, tof_tilt_deg=tilt)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(int(shank_scale * 10))
    n = 128
    lo, hi = m.jnt_range[1:, 0].copy(), m.jnt_range[1:, 1].copy()
    lo[[1, 2, 4, 5, 7, 8, 10, 11]] = -math.pi
    hi[[1, 2, 4, 5, 7, 8, 10, 11]] = math.pi
    q = rng.uniform(lo, hi, (n, 12))
    base_pos = rng.uniform(-2, 2, (n, 3))
    base_quat = rng.normal(size=(n, 4))
    base_quat /= np.linalg.norm(base_quat, axis=1, keepdims=True)
    foot_ids = _ids(m, mujoco.mjtObj.mjOBJ_GEOM, constants.FOOT_GEOMS)
    site_ids = _ids(m, mujoco.mjtObj.mjOBJ_SITE, constants.TOF_SITES)
    knee_ids = _ids(m, mujoco.mjtObj.mjOBJ_GEOM, tuple(f"{leg}_knee" for leg in constants.FEET))
    ref = {k: np.zeros((n, 4, 3)) for k in ("foot_b", "foot_w", "tof_w", "knee_b", "knee_w")}
    ref_rot = {k: np.zeros((n, 4, 3, 3)) for k in ("rot_b", "rot_w")}
    for i in range(n):
        for frame in ("b", "w"):
            d.qpos[7:] = q[i]
            d.qpos[:3] = base_pos[i] if frame == "w" else 0.0
            d.qpos[3:7] = base_quat[i] if frame == "w" else (1, 0, 0, 0)
            mujoco.mj_kinematics(m, d)
            ref[f"foot_{frame}"][i] = d.geom_xpos[foot_ids]
            ref[f"knee_{frame}"][i] = d.geom_xpos[knee_ids]
            ref_rot[f"rot_{frame}"][i] = d.site_xmat[site_ids].reshape(4, 3, 3)
            if frame == "w":
                ref["tof_w"][i] = d.site_xpos[site_ids]
    fk = jax.jit(forward_kinematics, static_argnums=(1, 2))(jp.asarray(q), shank_scale, tilt)
    np.testing.assert_allclose(fk.foot_pos, ref["foot_b"], atol=1e-5)
    np.testing.assert_allclose(fk.tof_pos, ref["foot_b"], atol=1e-5)
    np.testing.assert_allclose(fk.tof_rot, ref_rot["rot_b"], atol=1e-5)
    np.testing.assert_allclose(fk.knee_pos, ref["knee_b"], atol=1e-5)
    qpos = np.concatenate([base_pos, base_quat, q], axis=1)
    fkw = world_foot_kinematics(jp.asarray(qpos), shank_scale, tilt)
    np.testing.assert_allclose(fkw.foot_pos, ref["foot_w"], atol=1e-5)
    np.testing.assert_allclose(fkw.tof_pos, ref["tof_w"], atol=1e-5)
    np.testing.assert_allclose(fkw.tof_rot, ref_rot["rot_w"], atol=1e-5)
    np.testing.assert_allclose(fkw.knee_pos, ref["knee_w"], atol=1e-5)


def test_shank_scale_scales_kfe_to_foot_only():
    for s in (0.8, 1.2):
        m = make_model(shank_scale=s)
        m1 = make_model()
        np.testing.assert_allclose(m.body_mass, m1.body_mass)
        np.testing.assert_allclose(m.body_inertia, m1.body_inertia)
        np.testing.assert_allclose(m.body_ipos, m1.body_ipos)
        for leg in constants.FEET:
            g, g1 = m.geom(f"{leg}_foot"), m1.geom(f"{leg}_foot")
            np.testing.assert_allclose(g.pos, s * g1.pos, atol=1e-12)
            np.testing.assert_allclose(m.site(f"{leg}_tof").pos, s * g1.pos, atol=1e-12)
            # LF: KFE -> foot centre (0.100, 0.01411, -0.36208), mirrored
            sx, sy = kin.leg_signs(leg)
            np.testing.assert_allclose(g1.pos, [0.1 * sx, 0.01411 * sy, -0.36208], atol=1e-12)


@pytest.mark.parametrize("tilt", [0.0, 15.0, 45.0])
def test_tof_axis_convention_at_zero(tilt):
    """At q = 0 (base at identity) the optical axis is (0, +-sin t, -cos t), site x = +x."""
    m = make_model(tof_tilt_deg=tilt)
    d = mujoco.MjData(m)
    d.qpos[3] = 1.0
    mujoco.mj_kinematics(m, d)
    t = math.radians(tilt)
    for leg, site in zip(constants.FEET, constants.TOF_SITES, strict=True):
        sy = 1.0 if leg[0] == "L" else -1.0
        r = d.site_xmat[m.site(site).id].reshape(3, 3)
        np.testing.assert_allclose(r[:, 2], [0.0, sy * math.sin(t), -math.cos(t)], atol=1e-9)
        np.testing.assert_allclose(r[:, 0], [1.0, 0.0, 0.0], atol=1e-9)
        # the site sits inside the foot sphere (at its centre)
        np.testing.assert_allclose(
            d.site_xpos[m.site(site).id], d.geom_xpos[m.geom(f"{leg}_foot").id], atol=1e-12
        )


def test_nominal_stance_height(m_plane):
    """Keyframe 'standing': feet just touch z = 0 at base z ~ 0.589 m (FK of the ANYmal-D URDF in the IsaacLab stance)."""
    m = m_plane
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("standing").id)
    np.testing.assert_allclose(d.qpos, default_qpos())
    np.testing.assert_allclose(d.qpos[7:], constants.DEFAULT_POSE)
    assert d.qpos[2] == pytest.approx(constants.NOMINAL_BASE_HEIGHT_M, abs=1e-3)
    assert nominal_base_height() == pytest.approx(d.qpos[2], abs=1e-6)
    mujoco.mj_kinematics(m, d)
    feet = d.geom_xpos[_ids(m, mujoco.mjtObj.mjOBJ_GEOM, constants.FOOT_GEOMS)]
    np.testing.assert_allclose(feet[:, 2], FOOT_R, atol=1e-6)  # all four touch, none below
    # foot-sphere centres in the 0.4/0.8 stance: (+-0.4951, +-0.3096) (FK of the ANYmal-D URDF)
    np.testing.assert_allclose(np.abs(feet[:, :2]), [[0.4951, 0.3096]] * 4, atol=1e-4)
    # 1 mm lower: MuJoCo's collision finds exactly the four feet touching the ground
    d.qpos[2] -= 0.001
    mujoco.mj_forward(m, d)
    touching = {m.geom(c.geom2).name for c in d.contact[: d.ncon]}
    touching |= {m.geom(c.geom1).name for c in d.contact[: d.ncon]}
    assert touching == {"terrain", *constants.FOOT_GEOMS}


@pytest.mark.parametrize(
    "kwargs",
    [
        {"shank_scale": 0.79},
        {"shank_scale": 1.21},
        {"tof_tilt_deg": -1.0},
        {"tof_tilt_deg": 46.0},
        {"foot_radius_m": 0.019},
        {"foot_radius_m": 0.051},
        {"armature_kg": 0.1},
        {"cone": "round"},
        {"iterations": 0},
        {"solref_timeconst": 0.005},
    ],
)
def test_bad_input_raises(kwargs):
    with pytest.raises(ValueError, match=next(iter(kwargs)).split("_kg")[0]):
        make_model(**kwargs)


def test_bad_fk_input_raises():
    with pytest.raises(ValueError, match="shank_scale"):
        forward_kinematics(jp.zeros(12), 1.5)
    with pytest.raises(ValueError, match=r"\(\.\.\., 12\)"):
        forward_kinematics(jp.zeros(11))


def test_config_matches_model_defaults():
    cfg = _env.get_section()
    model_cfg = dict(cfg.model)
    assert model_cfg.pop("shank_scale") == 1.0
    assert model_cfg.pop("foot_radius_m") == FOOT_R
    assert model_cfg == DEFAULT_TUNING
    m = make_model(**cfg.model)  # config unpacks straight into make_model
    assert m.opt.iterations == cfg.model.iterations
    np.testing.assert_allclose(m.dof_armature[6:], cfg.model.armature)
    tau = pd_torque(jp.ones(12), jp.zeros(12), jp.zeros(12), **cfg.control)
    np.testing.assert_allclose(tau, 80.0)  # kp * 1 rad = 80 N m = the limit


# --------------------------------------------------------------------------------------------
# PD law.


def test_pd_torque_hand_values():
    z = jp.zeros(12)
    # 80 * 0.1 - 2 * 1 = 6 N m, inside all limits
    tau = pd_torque(z + 0.1, z, z + 1.0, 80.0, 2.0)
    np.testing.assert_allclose(tau, 6.0, rtol=1e-6)
    # large errors clip at +-80 N m
    np.testing.assert_allclose(pd_torque(z + 2.0, z, z, 80.0, 2.0), 80.0)
    np.testing.assert_allclose(pd_torque(z - 2.0, z, z, 80.0, 2.0), -80.0)
    # DC-motor line at qd = +5 rad/s: upper = 120 (1 - 5 / 8.5) = 49.4118, lower = -80
    qd = z + 5.0
    np.testing.assert_allclose(pd_torque(z + 2.0, z, qd, 80.0, 0.0), 49.411765, rtol=1e-6)
    np.testing.assert_allclose(pd_torque(z - 2.0, z, qd, 80.0, 0.0), -80.0)
    # moving at -5 rad/s: driving torque (negative) limited to -49.41, braking gets the full 80
    np.testing.assert_allclose(pd_torque(z - 2.0, z, -qd, 80.0, 0.0), -49.411765, rtol=1e-6)
    np.testing.assert_allclose(pd_torque(z + 2.0, z, -qd, 80.0, 0.0), 80.0)
    # beyond the velocity limit no driving torque is left; full torque up to 8.5 / 3 rad/s
    np.testing.assert_allclose(pd_torque(z + 2.0, z, z + 9.0, 80.0, 0.0), 0.0)
    np.testing.assert_allclose(pd_torque(z + 2.0, z, z + 2.8, 80.0, 0.0), 80.0)
    # constant clip only
    np.testing.assert_allclose(pd_torque(z + 2.0, z, qd, 80.0, 0.0, saturation_torque=None), 80.0)
    # per-joint gains broadcast
    kp = jp.arange(12.0)
    np.testing.assert_allclose(pd_torque(z + 0.5, z, z, kp, 0.0), 0.5 * np.arange(12.0))


# --------------------------------------------------------------------------------------------
# Standing in MJX (PD in JAX at 200 Hz, targets at 50 Hz).

STAND_HF_Z = 0.3  # flat hfield at this height, so that an unwritten hfield (z = -1) fails


def _stand(hfield, seconds):
    m = make_model(hfield)
    mx = mjx.put_model(m)
    ground_z = 0.0 if hfield is None else STAND_HF_Z
    qpos = default_qpos(base_height=ground_z + nominal_base_height() + 0.02)  # drop from 2 cm
    d0 = jax.jit(mjx.forward)(mx, mjx.make_data(mx).replace(qpos=jp.asarray(qpos, jp.float32)))
    foot_ids = _ids(m, mujoco.mjtObj.mjOBJ_GEOM, constants.FOOT_GEOMS)
    target = jp.asarray(constants.DEFAULT_POSE, jp.float32)
    cfg = _env.get_control_section()

    @jax.jit
    def run(d):
        def body(d, _):
            d, _ = control_step(mx, d, target, **cfg)
            return d, (d.qpos[2], d.geom_xpos[foot_ids])

        return jax.lax.scan(body, d, None, length=int(round(seconds / constants.CONTROL_DT_S)))

    _, (h, feet) = run(d0)
    return ground_z, np.asarray(h), np.asarray(feet)


def _check_standing(ground_z, h, feet):
    settle = int(round(0.3 / constants.CONTROL_DT_S))  # landed and settled after 0.3 s
    assert np.isfinite(h).all() and np.isfinite(feet).all()
    # base height within 5 cm of nominal for the whole run after landing
    err = np.abs(h[settle:] - ground_z - constants.NOMINAL_BASE_HEIGHT_M)
    assert err.max() < 0.05, err.max()
    # every foot on the ground and within 5 cm of where it landed
    landed = feet[settle]
    np.testing.assert_allclose(landed[:, 2], ground_z + FOOT_R, atol=0.005)
    drift = np.linalg.norm(feet[settle:] - landed, axis=-1)
    assert drift.max() < 0.05, drift.max()
    return err.max(), drift.max()


@pytest.mark.slow
def test_pd_standing_plane_5s():
    _check_standing(*_stand(None, 5.0))


# Slow since 2026-12-02 (MJX on CPU, ~80-180 s: the fast suite reached 15 min); the fast suite
# keeps MJX's one-step agreement with mj_step (tests/test_physics.py) and the C backend's
# standing test.
@pytest.mark.slow
def test_pd_standing_flat_hfield_5s():
    hf = Heightfield(heights=jp.full((60, 60), STAND_HF_Z), x0_m=-1.2, y0_m=-1.2, cell_m=0.04)
    _check_standing(*_stand(hf, 5.0))


@pytest.mark.slow
def test_pd_standing_plane_20s():
    _check_standing(*_stand(None, 20.0))


@pytest.mark.slow
def test_pd_standing_flat_hfield_20s():
    hf = Heightfield(heights=jp.full((60, 60), STAND_HF_Z), x0_m=-1.2, y0_m=-1.2, cell_m=0.04)
    _check_standing(*_stand(hf, 20.0))


def test_body_collision_off_keeps_geoms_feet_only():
    m = make_model(body_collision=False)
    d = mujoco.MjData(m)
    assert m.geom("LF_knee").id >= 0 and m.geom("base_0").id >= 0
    rng = np.random.default_rng(1)
    feet = set(_ids(m, mujoco.mjtObj.mjOBJ_GEOM, constants.FOOT_GEOMS))
    hits = 0
    for _ in range(200):
        d.qpos[:] = default_qpos(base_height=rng.uniform(0.05, 0.4))
        d.qpos[7:] = rng.uniform(-math.pi, math.pi, 12)
        mujoco.mj_forward(m, d)
        for c in d.contact[: d.ncon]:
            assert {c.geom1, c.geom2} - {m.geom("terrain").id} <= feet
        hits += d.ncon
    assert hits > 0


def test_mjx_forward_matches_mujoco_c(m_plane):
    """MJX (float32) joint accelerations equal MuJoCo C's, in the air and with feet in contact."""
    m = m_plane
    mx = mjx.put_model(m)
    fwd = jax.jit(mjx.forward)
    rng = np.random.default_rng(0)
    for base_height, min_contacts in ((2.0, 0), (0.585, 2)):
        d = mujoco.MjData(m)
        d.qpos[:] = default_qpos(base_height=base_height)
        d.qpos[7:] += rng.uniform(-0.1, 0.1, 12)
        d.qvel[:] = rng.normal(0.0, 0.3, 18)
        d.ctrl[:] = rng.uniform(-30.0, 30.0, 12)
        mujoco.mj_forward(m, d)
        assert d.ncon >= min_contacts
        dx = fwd(mx, mjx.put_data(m, d))
        scale = np.abs(d.qacc).max()
        np.testing.assert_allclose(dx.qacc, d.qacc, atol=1e-5 * scale)


def test_contact_parameters_come_from_robot_geoms():
    """Foot contacts use foot_friction, base/knee contacts body_friction and body_condim."""
    m = make_model(foot_friction=0.7, body_friction=0.3, body_condim=1)
    d = mujoco.MjData(m)
    d.qpos[:] = default_qpos(base_height=0.05)  # base and knees pushed into the ground
    mujoco.mj_forward(m, d)
    kinds = set()
    for c in d.contact[: d.ncon]:
        name = m.geom(c.geom2 if c.geom1 == m.geom("terrain").id else c.geom1).name
        foot = name in constants.FOOT_GEOMS
        kinds.add("foot" if foot else name.split("_")[0] if name.startswith("base") else "knee")
        assert c.dim == (3 if foot else 1)
        if foot:
            assert c.friction[0] == pytest.approx(0.7)
        else:
            assert c.friction[0] == pytest.approx(0.3)
    assert kinds == {"foot", "base", "knee"}
