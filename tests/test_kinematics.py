"""Machine templates, inverse and forward kinematics (MATH.md §A4, eq. (16))."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from engine.errors import Cancelled, InputError
from engine.kinematics import (
    angle_between,
    demo_eye_path,
    eye_chain,
    eye_pose,
    forward_kinematics,
    inverse_kinematics,
    list_machines,
    load_machine,
    parse_machine,
    reproduced_fibre_dir,
)

MACHINES = ["gantry6", "lathe2", "lathe3", "lathe4", "robot_cell"]
ROOT = Path(__file__).resolve().parents[1]


def _path(kind: str, n: int = 3000, circuits: int = 2):
    return demo_eye_path(kind, n=n, circuits=circuits)


def test_shipped_templates_load():
    assert set(MACHINES) <= set(list_machines())
    n_axes = {"lathe2": 2, "lathe3": 3, "lathe4": 4, "gantry6": 6, "robot_cell": 8}
    for name in MACHINES:
        m = load_machine(name)
        assert len(m.axes) == n_axes[name]
        assert m.axis_index("mandrel") is not None
    robot = load_machine("robot_cell")
    # the arm's 7 controlled coordinates carry the limits of seed 003's example
    vmax = [robot.axes[robot.axis_index(f"joint{k}")].max_speed for k in range(1, 7)]
    assert vmax == [1.396, 1.309, 1.222, 1.230, 1.229, 1.914]
    assert robot.axes[robot.axis_index("track")].max_speed == 1866.667


@pytest.mark.parametrize("name", MACHINES)
@pytest.mark.parametrize("kind", ["helix", "dome"])
def test_forward_replay_reproduces_eye_and_fibre(name, kind):
    m = load_machine(name)
    p = _path(kind)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    assert ap.ok, ap.message()
    eye, d = forward_kinematics(m, ap.q, p.contact_xyz)
    assert np.abs(eye - ap.eye_xyz).max() < 1e-6
    assert angle_between(d, reproduced_fibre_dir(m, ap)).max() < 1e-9
    if m.axis_index("cross") is not None or m.kind == "robot":
        # enough DOF: the eye is exactly the payout stage's eye
        assert np.abs(ap.eye_xyz - p.eye_xyz).max() < 1e-9
        assert np.all(ap.eye_shift == 0)
    if m.fibre_mode == "full":
        assert angle_between(d, p.fibre_dir).max() < 1e-9


def test_fixed_radius_eye_slides_along_the_fibre_line():
    m = load_machine("lathe2")
    p = _path("dome")
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    assert ap.ok
    r = np.hypot(ap.eye_xyz[:, 0], ap.eye_xyz[:, 1])
    assert np.abs(r - m.eye_radius).max() < 1e-9
    # still on the free-fibre line, on the eye side of the contact point
    rel = ap.eye_xyz - p.contact_xyz
    assert np.linalg.norm(np.cross(rel, p.fibre_dir), axis=1).max() < 1e-9
    assert np.einsum("ij,ij->i", rel, p.fibre_dir).min() > 0
    # helix path: eye already at the eye radius, nothing to slide
    h = _path("helix")
    aph = inverse_kinematics(m, h.eye_xyz, h.fibre_dir, h.contact_xyz)
    assert np.abs(aph.eye_shift).max() < 1e-9


def test_lathe_closed_form_against_cylindrical_coordinates():
    """Independent: cross feed = eye radius, carriage = z + datum, mandrel angle = eye azimuth (V)."""
    m = load_machine("lathe3")
    p = _path("dome")
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    names = list(ap.axis_names)
    V = np.unwrap(np.arctan2(p.eye_xyz[:, 1], p.eye_xyz[:, 0]))
    A = ap.q[:, names.index("A")]
    assert np.allclose(A - A[0], np.degrees(V - V[0]), atol=1e-9)
    assert np.allclose(ap.q[:, names.index("Y")], np.hypot(p.eye_xyz[:, 0], p.eye_xyz[:, 1]), atol=1e-9)
    assert np.allclose(ap.q[:, names.index("X")], p.eye_xyz[:, 2] + 600.0, atol=1e-9)
    # mandrel monotone (counts up), angles unwrapped: no 360-degree jumps
    assert np.all(np.diff(A) > 0)


@pytest.mark.parametrize("name", MACHINES)
def test_angles_unwrapped_and_continuous(name):
    m = load_machine(name)
    p = _path("dome", n=4000)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    q = m.to_internal(ap.q)
    rot = [k for k, a in enumerate(m.axes) if a.type == "rotary"]
    # neighbouring points are ~0.6 mm apart on the line: no axis may jump by a large angle
    assert np.abs(np.diff(q[:, rot], axis=0)).max() < 0.2


@pytest.mark.parametrize("name", MACHINES)
def test_fast_eye_pose_equals_product_of_4x4_transforms(name):
    """eq. (16): both sides as products of homogeneous transforms vs. the column-wise fast path."""
    m = load_machine(name)
    p = _path("dome", n=500, circuits=1)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    qi = m.to_internal(ap.q)
    T = eye_chain(m, qi)
    pw, zw = eye_pose(m, qi)
    assert np.abs(T[:, :3, 3] - pw).max() < 1e-9
    assert np.abs(T[:, :3, 2] - zw).max() < 1e-12
    # mandrel chain: p_W = Rz(theta) p_M, so the eye in the mandrel frame is Rz(-theta) T e
    th = qi[:, m.axis_index("mandrel")]
    for i in range(0, 500, 97):
        c, s = math.cos(th[i]), math.sin(th[i])
        Mz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
        e_m = np.linalg.solve(Mz, T[i] @ np.array([0, 0, 0, 1.0]))[:3]
        assert np.allclose(e_m, ap.eye_xyz[i], atol=1e-8)


def _dh(theta, d, a, alpha):
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d],
                     [0, 0, 0, 1.0]])


def test_robot_chain_against_textbook_dh_matrices():
    m = load_machine("robot_cell")
    rng = np.random.default_rng(1)
    q = rng.uniform(-1, 1, (20, len(m.axes)))
    T = eye_chain(m, q)
    for i in range(20):
        M = np.eye(4)
        M[2, 3] = q[i, m.axis_index("track")]
        M = M @ m.base
        for k, row in enumerate(m.dh):
            M = M @ _dh(q[i, m.axis_index(f"joint{k + 1}")] + row.theta0, row.d, row.a, row.alpha)
        M = M @ m.tool
        assert np.allclose(M, T[i], atol=1e-9)


def test_robot_eye_frame_band_direction():
    m = load_machine("robot_cell")
    p = _path("helix", n=1500, circuits=1)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    qi = m.to_internal(ap.q)
    T = eye_chain(m, qi)
    th = qi[:, m.axis_index("mandrel")]
    x_w = T[:, :3, 0]
    x_m = np.stack([np.cos(th) * x_w[:, 0] + np.sin(th) * x_w[:, 1],
                    -np.sin(th) * x_w[:, 0] + np.cos(th) * x_w[:, 1], x_w[:, 2]], axis=1)
    nr = p.contact_xyz * np.array([1, 1, 0.0])
    w = np.cross(p.fibre_dir, nr)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    # the slot is symmetric (band_symmetric): eye x is +w or -w, whichever keeps the wrist still
    ang = angle_between(x_m, w)
    assert np.minimum(ang, np.pi - ang).max() < 1e-9
    # without the symmetry it is +w exactly
    data = _template("robot_cell")
    data["robot"]["band_symmetric"] = False
    m2 = parse_machine(data, "asym.toml")
    ap2 = inverse_kinematics(m2, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    T2 = eye_chain(m2, m2.to_internal(ap2.q))
    th2 = m2.to_internal(ap2.q)[:, m2.axis_index("mandrel")]
    x2 = np.stack([np.cos(th2) * T2[:, 0, 0] + np.sin(th2) * T2[:, 1, 0],
                   -np.sin(th2) * T2[:, 0, 0] + np.cos(th2) * T2[:, 1, 0], T2[:, 2, 0]], axis=1)
    assert angle_between(x2, w).max() < 1e-9


def test_state_progress_and_cancel(state):
    m = load_machine("robot_cell")
    p = _path("helix", n=5000, circuits=1)
    inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz, state=state)
    assert state.fractions[0] == 0.0 and state.fractions[-1] == 1.0
    from engine.state import RecordingState
    with pytest.raises(Cancelled):
        inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz, state=RecordingState(cancel_after=0))


def _template(name: str) -> dict:
    with open(ROOT / "resources" / "machines" / f"{name}.toml", "rb") as fh:
        return tomllib.load(fh)


def test_position_limit_violation_located():
    data = _template("lathe3")
    data["axes"][2]["max"] = 150.0          # cross feed Y: eye radius up to ~160+ on the dome path
    m = parse_machine(data, "narrow.toml")
    p = _path("dome")
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    assert not ap.ok
    r = np.hypot(p.eye_xyz[:, 0], p.eye_xyz[:, 1])
    over = r > 150.0
    vs = [v for v in ap.violations if v.kind == "position" and v.axis == "Y"]
    assert vs
    assert vs[0].index == int(np.flatnonzero(over)[0])
    assert max(v.amount for v in vs) == pytest.approx(r.max() - 150.0, abs=1e-9)
    assert sum(v.count for v in vs) == int(over.sum())
    assert "axis Y" in vs[0].message and "exceeds the limit 150" in vs[0].message


def test_workspace_and_reverse_violations():
    m = load_machine("lathe2")
    p = _path("helix")
    # eye radius inside the mandrel: the fibre line never gets there
    data = _template("lathe2")
    data["eye_radius"] = 50.0
    ap = inverse_kinematics(parse_machine(data, "x.toml"), p.eye_xyz, p.fibre_dir, p.contact_xyz)
    assert any(v.kind == "workspace" and v.index == 0 for v in ap.violations)
    # a path that turns back: the mandrel would reverse
    eye = p.eye_xyz.copy()
    k = 1000
    c, s = math.cos(-0.5), math.sin(-0.5)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    eye[k:] = eye[k:] @ rot.T
    con = p.contact_xyz.copy()
    con[k:] = con[k:] @ rot.T
    d = p.fibre_dir.copy()
    d[k:] = d[k:] @ rot.T
    ap2 = inverse_kinematics(m, eye, d, con)
    rev = [v for v in ap2.violations if v.kind == "reverse"]
    assert rev and rev[0].index == k and rev[0].axis == "A"
    assert rev[0].amount == pytest.approx(math.degrees(0.5), abs=0.5)      # deg, the axis' units
    assert "turns back" in rev[0].message


@pytest.mark.parametrize(
    ("mutate", "field"),
    [
        (lambda d: d.pop("axes"), "axes"),
        (lambda d: d["axes"][0].__setitem__("max_speed", "fast"), "axes[0].max_speed"),
        (lambda d: d["axes"][0].__setitem__("max_speed", -1.0), "axes[0].max_speed"),
        (lambda d: d["axes"][1].__setitem__("role", "spindle"), "axes[1].role"),
        (lambda d: d["axes"][1].__setitem__("units", "deg"), "axes[1].units"),
        (lambda d: d["axes"][1].__setitem__("name", "A"), "axes"),
        (lambda d: d["axes"][1].__setitem__("min", 5000.0), "axes[1].min"),
        (lambda d: d.__setitem__("kind", "delta"), "kind"),
        (lambda d: d.pop("eye_radius"), "eye_radius"),
        (lambda d: d.__setitem__("mandrel_phase", "contact"), "mandrel_phase"),
    ],
)
def test_bad_template_names_file_and_field(tmp_path, mutate, field):
    data = _template("lathe2")
    mutate(data)
    import tomli_w

    f = tmp_path / "bad_machine.toml"
    f.write_bytes(tomli_w.dumps(data).encode())
    with pytest.raises(InputError) as ei:
        load_machine(f)
    assert ei.value.location.field == field
    assert ei.value.location.file == str(f)
    assert "bad_machine.toml" in str(ei.value)


def test_bad_robot_template_and_unknown_machine(tmp_path):
    data = _template("robot_cell")
    data["robot"]["dh"] = data["robot"]["dh"][:5]
    with pytest.raises(InputError, match="6 rows") as ei:
        parse_machine(data, "r.toml")
    assert ei.value.location.field == "robot.dh"
    data = _template("robot_cell")
    data["robot"]["band_symmetric"] = "yes"
    with pytest.raises(InputError) as ei:
        parse_machine(data, "r.toml")
    assert ei.value.location.field == "robot.band_symmetric"
    f = tmp_path / "broken.toml"
    f.write_text("kind = [\n")
    with pytest.raises(InputError, match="TOML"):
        load_machine(f)
    with pytest.raises(InputError, match="unknown machine"):
        load_machine("no_such_machine")


def test_user_machine_file_is_a_machine(tmp_path):
    """Adding a machine is adding a file: a copy of lathe3 with other letters and units works."""
    data = _template("lathe3")
    data["axes"][0].update(name="C", units="rev", sign=1)
    data["axes"][1].update(name="Z", units="inch", offset=0.0, min=-100.0, max=100.0, max_speed=20.0)
    import tomli_w

    f = tmp_path / "my_winder.toml"
    f.write_bytes(tomli_w.dumps(data).encode())
    m = load_machine(f)
    assert m.name == "my_winder" and m.axis_names == ("C", "Z", "Y")
    p = _path("dome", n=1000, circuits=1)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    eye, _ = forward_kinematics(m, ap.q)
    assert np.abs(eye - p.eye_xyz).max() < 1e-9
    assert np.allclose(ap.q[:, 1], p.eye_xyz[:, 2] / 25.4)
    assert np.all(np.diff(ap.q[:, 0]) < 0)          # sign +1: counts down while winding


def test_bad_inputs():
    m = load_machine("lathe3")
    p = _path("helix", n=100, circuits=1)
    with pytest.raises(InputError, match="unit vectors"):
        inverse_kinematics(m, p.eye_xyz, 2 * p.fibre_dir, p.contact_xyz)
    bad = p.eye_xyz.copy()
    bad[7, 1] = np.nan
    with pytest.raises(InputError, match="point 7"):
        inverse_kinematics(m, bad, p.fibre_dir, p.contact_xyz)
    with pytest.raises(InputError, match="shape"):
        inverse_kinematics(m, p.eye_xyz[:, :2], p.fibre_dir, p.contact_xyz)


def test_process_parameter_passes_through():
    m = load_machine("lathe3")
    p = _path("helix", n=200, circuits=1)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz, x=p.x)
    assert np.array_equal(ap.x, p.x)
    assert inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz).x is None
    with pytest.raises(InputError, match="x must have shape"):
        inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz, x=p.x[:10])


def test_fixed_radius_eye_slides_forward_not_behind_the_contact():
    """Near a pole the fibre leaves the surface pointing inwards: the line crosses the eye radius
    once behind the contact point (nearer to the given eye) and once in front - the front one is used."""
    m = load_machine("lathe2")
    d = np.array([[-0.5, 0.3, 0.8], [-0.5, 0.31, 0.8]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = np.array([[150.0, 0.0, 0.0], [150.0, 0.5, 0.2]])
    eye = c + 20.0 * d               # crossings of r = 160 at free lengths ~ -20 (nearer) and ~ +456
    ap = inverse_kinematics(m, eye, d, c)
    assert ap.ok, ap.message()
    rel = ap.eye_xyz - c
    assert np.all(np.einsum("ij,ij->i", rel, d) > 0)
    assert np.allclose(np.hypot(ap.eye_xyz[:, 0], ap.eye_xyz[:, 1]), m.eye_radius)
    assert np.linalg.norm(np.cross(rel, d), axis=1).max() < 1e-9


def test_unwrap_angles_is_numpy_unwrap_bit_for_bit():
    """The sparse unwrap used on every axis path equals numpy.unwrap exactly: random walks with wraps,
    steps of exactly ±π, large jumps, a NaN, and paths without any wrap."""
    from engine.kinematics import unwrap_angles

    rng = np.random.default_rng(11)
    walks = [np.angle(np.exp(1j * np.cumsum(rng.normal(0.0, 0.3, 5000)))),
             np.angle(np.exp(1j * np.cumsum(rng.uniform(0.0, 0.2, 20000)))),
             rng.uniform(-10.0, 10.0, 3000), rng.uniform(-10.0, 10.0, 60000),
             np.array([0.0, np.pi, 0.0, -np.pi, 0.0, 2 * np.pi, -3.5, 3.5]),
             np.linspace(-1.0, 1.0, 100)]
    nan = walks[0].copy()
    nan[100] = np.nan
    walks.append(nan)
    for w in walks:
        got, ref = unwrap_angles(w), np.unwrap(w)
        assert np.array_equal(got, ref, equal_nan=True)
    assert np.array_equal(unwrap_angles(np.zeros((3, 4))), np.unwrap(np.zeros((3, 4))))


def _robot_big_step_path():
    """The demo helix with a stretch of points cut out: one path step where the joints move > 0.5 rad."""
    m = load_machine("robot_cell")
    p = _path("helix", n=1500, circuits=1)
    dense = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    qd = m.to_internal(dense.q)
    jc = [m.axis_index(f"joint{k}") for k in range(1, 7)]
    step = np.abs(np.diff(qd[:, jc], axis=0)).max(axis=1)
    k0 = int(np.argmax(step))                       # cut around the fastest wrist motion
    keep = np.ones(p.x.size, bool)
    cut = np.arange(k0 + 1, min(p.x.size - 2, k0 + 1 + 200))
    keep[cut] = False
    while np.abs(qd[cut[-1] + 1, jc] - qd[k0, jc]).max() < 0.6:      # make the step big enough
        cut = np.arange(k0 + 1, cut[-1] + 50)
        keep[cut] = False
    return m, p, keep, qd, jc


def test_robot_big_joint_step_on_one_branch_is_not_a_switch():
    """A joint step above 0.5 rad between two path points is checked by continuation through the
    in-between poses: on the same branch it is no violation, and the joints equal those of the dense
    path (solved point by point, the independent reference)."""
    m, p, keep, qd, jc = _robot_big_step_path()
    ap = inverse_kinematics(m, p.eye_xyz[keep], p.fibre_dir[keep], p.contact_xyz[keep])
    qs = m.to_internal(ap.q)
    assert np.abs(np.diff(qs[:, jc], axis=0)).max() > 0.5            # the case is exercised
    assert not [v for v in ap.violations if v.kind == "ik"], [v.message for v in ap.violations]
    assert np.abs(qs[:, jc] - qd[keep][:, jc]).max() < 1e-6


def test_robot_branch_switch_found_by_continuation():
    """The wrist flip (j4 + pi, -j5, j6 + pi) puts the eye in the same pose: continuation from the point
    before does not reach it, so a path that jumps to it is a branch switch."""
    from engine.kinematics import _continue_steps, _robot_chain

    m, p, keep, qd, jc = _robot_big_step_path()
    i = np.flatnonzero(~keep)
    a, b = int(i[0] - 1), int(i[-1] + 1)
    track = qd[[a, b], m.axis_index("track")]
    j = qd[[a, b]][:, jc]
    R, pw, _, _ = _robot_chain(m, track, j)
    flipped = j.copy()
    flipped[1, 3:] += (np.pi, 0.0, np.pi)
    flipped[1, 4] = -j[1, 4]
    R2, pw2, _, _ = _robot_chain(m, track, flipped)
    assert np.abs(pw2 - pw).max() < 1e-9 and np.abs(R2 - R).max() < 1e-9     # the same eye pose
    end, worst = _continue_steps(m, track, pw, R, j, np.array([0]))
    assert np.abs(end[0] - j[1]).max() < 1e-6 and worst[0] < 0.5        # reaches its own branch
    end2, _ = _continue_steps(m, track, pw, R, flipped, np.array([0]))
    assert np.abs(end2[0] - flipped[1]).max() > 1.0                      # not the flipped one


def test_a_machine_template_is_read_once_until_its_file_changes(tmp_path: Path) -> None:
    """load_machine keeps what it read: the same (immutable) template for the same unchanged file, its
    arrays read-only; a file edited since (another size, another time) is read again; the template equals
    one parsed afresh."""
    import os

    from engine.kinematics import MACHINES_DIR, parse_machine

    a, b = load_machine("robot_cell"), load_machine("robot_cell")
    assert a is b and not a.base.flags.writeable and not a.tool.flags.writeable
    fresh = parse_machine(tomllib.loads((MACHINES_DIR / "robot_cell.toml").read_text(encoding="utf-8")),
                          file=str(MACHINES_DIR / "robot_cell.toml"), name="robot_cell")
    assert fresh.axis_names == a.axis_names and np.array_equal(fresh.base, a.base) and fresh.dh == a.dh
    path = tmp_path / "mine.toml"
    text = (MACHINES_DIR / "lathe2.toml").read_text(encoding="utf-8")
    path.write_text(text, encoding="utf-8")
    first = load_machine(path)
    assert load_machine(path) is first
    path.write_text(text.replace('title = "', 'title = "edited ', 1), encoding="utf-8")
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    second = load_machine(path)
    assert second is not first and second.title.startswith("edited ") and not first.title.startswith("edited ")
