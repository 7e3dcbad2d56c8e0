"""The compiled kernels' own guarantees: sums round as numpy's, the first-run compilation is
recorded, the simulator reads MuJoCo's contacts in place correctly."""

from __future__ import annotations

from typing import Any

import numpy as np

from dlovr.geometry.kernels import np_sum


def test_np_sum_rounds_as_numpy_sums():
    rng = np.random.default_rng(0)
    for n in [*range(0, 140), 255, 256, 257, 1000, 1025, 4097]:
        a = rng.normal(size=n) * 10.0 ** rng.integers(-6, 6, size=n)
        assert np_sum(a) == a.sum(), n  # bit for bit, the order of numpy's pairwise summation
        assert np_sum(np.abs(a)) == np.abs(a).sum(), n


def test_an_inner_kernel_called_from_python_raises_instead_of_crashing():
    import pytest

    from dlovr.geometry.kernels import dot3

    with pytest.raises(TypeError, match="inner kernel"):
        dot3(1.0, 2.0, 3.0, 4.0, 5.0, 6.0)  # compiled without the wrapper Python would call


def test_warm_up_compiles_once_and_says_so():
    from dlovr.jit import kernels_warm
    from dlovr.sim.warmup import NOTICE, warm_up

    said: list[str] = []
    warm_up(said.append)  # compiles, or finds the kernels compiled by an earlier run
    assert kernels_warm()
    assert said in ([], [NOTICE])
    again: list[str] = []
    assert warm_up(again.append) == 0.0 and again == []


def test_warm_kernels_go_into_the_kernel_store(monkeypatch):
    """What an installation without kernels would take from the store: every kernel module's cache
    files and the warm marker (the round trip through a wheel: tests/test_install.py)."""
    from dlovr.jit import _KERNELS, store_dir
    from dlovr.sim.warmup import warm_up

    warm_up()
    store = store_dir()
    assert store is not None and store.is_dir()
    assert sorted(p.name for p in store.iterdir()) == sorted(_KERNELS)
    for module in _KERNELS:
        names = [p.name for p in (store / module).iterdir()]
        assert any(n.endswith(".nbi") for n in names) and any(n.endswith(".nbc") for n in names), module
    assert (store / "dlovr.sim.track_kernels" / "dlovr-kernels.warm").is_file()
    monkeypatch.setenv("DLOVR_KERNEL_STORE", "0")
    assert store_dir() is None


def test_contact_rows_read_in_place_match_mujocos_own_accessors():
    import mujoco

    from dlovr.scene import load_scene, scenes_dir
    from dlovr.script import load_script
    from dlovr.sim import Simulator

    sim = Simulator(load_scene("table"))
    for rec in sim.run(load_script(scenes_dir() / "table.script.toml")):
        if len(rec.contact_arrays) > 3:
            break
    d, m = sim.data, sim.model
    ca = rec.contact_arrays
    assert len(ca) == d.ncon > 3  # every contact is the rod's with the table
    c = d.contact
    np.testing.assert_array_equal(ca.dist, c.dist[: d.ncon])
    np.testing.assert_array_equal(ca.pos, c.pos[: d.ncon])
    np.testing.assert_array_equal(ca.normal, c.frame[: d.ncon, :3])
    np.testing.assert_array_equal(ca.segment, c.elem[: d.ncon, 1])
    force = np.zeros(6)
    for i in range(d.ncon):
        mujoco.mj_contactForce(m, d, i, force)
        assert ca.force[i] == force[0] or abs(ca.force[i] - force[0]) <= 1e-12 * max(1.0, abs(force[0]))
    assert ca.active.all() == (c.efc_address[: d.ncon] >= 0).all()


def test_records_and_states_made_without_init_are_the_constructors_objects():
    """StepRecord._of and ContactState._of (the per-step path) set exactly the dataclass fields, in
    order, to what the constructor sets, and stay frozen."""
    import dataclasses

    import pytest

    from dlovr.sim.simulator import StepRecord
    from dlovr.sim.tracker import ContactState

    for cls in (StepRecord, ContactState):
        fields = dataclasses.fields(cls)
        given = [f for f in fields if f.name != "state"]  # the record's state is set after
        values: list[Any] = [object() for _ in given]  # sentinels: the fields' types do not matter
        fast, slow = cls._of(*values), cls(*values)
        assert list(vars(fast)) == [f.name for f in fields] == list(vars(slow))
        assert all(vars(fast)[k] is vars(slow)[k] for k in vars(slow))
        frozen: Any = fast  # the assignment below is meant to fail
        with pytest.raises(dataclasses.FrozenInstanceError):
            frozen.step = 0


def test_packed_pieces_are_read_by_name_in_packing_order():
    """The kernels' named sections of the packed pieces are packing's sections, in its order, and
    each view has the shape the packed arrays say."""
    from dlovr.geometry import SceneGeometry, box_mesh
    from dlovr.geometry.kernels import Pieces, unpack
    from dlovr.geometry.packing import FLOAT_SECTIONS, INT_SECTIONS
    from dlovr.transforms import pose_matrix

    assert Pieces._fields == FLOAT_SECTIONS + INT_SECTIONS
    table = (box_mesh([1.0, 1.0, 0.05]), pose_matrix([0, 0, -0.025], [1, 0, 0, 0]))
    packed = SceneGeometry.from_meshes({"table": table}, radius=0.005).packed()
    g = getattr(unpack, "py_func", unpack)(packed.floats, packed.ints)  # the Python of the kernel
    n_p, n_f = len(g.nfaces), packed.width
    assert g.normals.shape == (n_p, n_f, 3) and g.label.shape == (n_p, n_f)
    assert g.tri_range.shape == g.outline_range.shape == (n_p * n_f + 1,)
    assert sum(a.size for a in g[: len(FLOAT_SECTIONS)]) == packed.floats.size


def test_the_trackers_work_sections_tile_their_arrays():
    """:func:`new_work` lays the sections out once, :class:`Work` names them: every section has its
    room, none overlaps the next, and what lasts is copied when the arrays grow."""
    from dlovr.sim import track_kernels as tk

    wi, wf = tk.new_work(n1=5, width=3, n_pieces=4, cap_c=16, cap_h=16)
    w = tk.work_views(wi, wf)
    assert w.kept.shape == (16, 4) and w.group.shape == (16, 3) and w.start.shape == (6,)
    assert w.pairs.shape == (5 * 4 + 2 * 16 + 16, 2) and w.qpts.shape == (5 + 16, 3)
    assert w.owner.shape == w.again.shape == (5 + 16,) and w.point_of.shape == (16,)
    starts = [int(wi[s]) for s in (tk.W_TOUCH, tk.W_KEPT, tk.W_GROUP, tk.W_START, tk.W_CHANGED)]
    assert starts == sorted(starts) and starts[0] == tk.W_HEAD
    w.touching[:3], w.group[:2] = [7, 8, 9], 5
    wi[tk.W_TOUCH_N] = 3
    wi2, wf2 = tk.new_work(n1=5, width=3, n_pieces=4, cap_c=32, cap_h=64, old=wi)
    w2 = tk.work_views(wi2, wf2)
    assert wi2[tk.W_TOUCH_N] == 3 and w2.touching[:3].tolist() == [7, 8, 9] and (w2.group[:2] == 5).all()
    lab_i, _ = tk.no_labels()
    assert lab_i[tk.L_K] < 0  # no labels


def _move_in_python(pos: Any, quat: Any, target_pos: Any, target_quat: Any, vmax: float, wmax: float):
    """The gripper's motion as the simulator ran it in Python floats before
    :func:`dlovr.sim.kernels.move_gripper` (the reference of its bits)."""
    import math

    from dlovr.transforms import dot, norm, slerp

    p, t = pos.tolist(), target_pos.tolist()
    if p != t:
        d0, d1, d2 = t[0] - p[0], t[1] - p[1], t[2] - p[2]
        dist = norm([d0, d1, d2])
        if dist <= vmax:
            pos[:] = target_pos
        else:
            f = vmax / dist
            pos[:] = [p[0] + d0 * f, p[1] + d1 * f, p[2] + d2 * f]
    q, tq = quat.tolist(), target_quat.tolist()
    if q != tq:
        c = dot(q, tq)
        angle = 2.0 * math.acos(min(1.0, abs(c)))
        quat[:] = target_quat if angle <= wmax else slerp(q, tq, wmax / angle)


def test_the_gripper_motion_kernel_rounds_as_python_floats():
    """Bit for bit the Python floats' motion, over random poses and targets: far and near (within
    the step's bounds), turns small and large, quaternions of either sign, not quite unit."""
    from dlovr.sim.kernels import move_gripper

    rng = np.random.default_rng(1)
    vmax, wmax = 0.25 * 0.002, 2.0 * 0.002
    for k in range(20000):
        pos = rng.normal(size=3) * 0.3
        scale = 10.0 ** rng.uniform(-6, 0)
        tpos = pos + rng.normal(size=3) * scale if k % 7 else pos.copy()
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat) * (1.0 + rng.normal() * 1e-12)
        tquat = quat + rng.normal(size=4) * 10.0 ** rng.uniform(-7, 0.3) if k % 5 else quat.copy()
        tquat *= (-1.0 if k % 3 == 0 else 1.0) / np.linalg.norm(tquat)
        want = pos.copy(), quat.copy()
        _move_in_python(*want, tpos, tquat, vmax, wmax)
        got = pos.copy(), quat.copy()
        move_gripper(*got, tpos, tquat, vmax, wmax)
        for w, g in zip(want, got, strict=True):
            assert w.tobytes() == g.tobytes(), (k, pos, quat, tpos, tquat)
