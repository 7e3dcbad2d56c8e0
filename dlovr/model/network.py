"""Transition networks merged from several demonstrations of one task (paper §VI, §VII).

Pure Python + numpy + networkx. Each demonstration contributes its kept contact situations (see
:func:`dlovr.recording.kept_states`) and its gripper pose track. The network has

- **nodes**: the distinct discrete situations (with face names), with how often they were visited and
  how long they held, their principal contacts, the stability of the least stable principal contact
  (``stable``, ``semi-stable``, ``instable``, or ``free`` when no environment contact exists) and the
  expected contact vector (the normalised sum of the principal contacts' vectors of eq. 2, world frame;
  the zero vector in free space, ``None`` when the input carries no vectors);
- **edges**: the transitions between consecutive kept situations, with their class
  (:func:`dlovr.model.transitions.classify_step`), how often they were demonstrated (``count``), the
  probability of leaving the source node along them (``count`` / all departures from the source), the
  durations (time from entering the source to entering the target, s), the demonstrated gripper motion
  (mean and spread of the world displacement, m; where it began and ended), their **risk**: ``none``
  for ``C``, ``E`` and ``-``, ``caution`` for ``T``, ``risky`` for ``I`` and ``S`` (docs/networks.md),
  and, for a classed edge, the **detection** of each class with parameters derived from the
  demonstrations' wrench around each occurrence (:mod:`dlovr.model.derivation`), merged as the median
  over the occurrences that gave a signal (the class's defaults where none did);
- **start** and **goal**: the most common first and last kept situation of the demonstrations (ties go
  to the one seen first).

Node ids are ``n1, n2, …`` in order of first appearance, so the same demonstrations in the same order
give the same network, bit for bit. Demonstrations of different scenes are refused
(:class:`NetworkError`). Frames and units: world frame, metres, seconds.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import networkx as nx
import numpy as np

from dlovr.inputs import InputError, parse_json, read_json, where_msg
from dlovr.model.derivation import WrenchSeries
from dlovr.model.discrete import DiscreteContact, DiscreteSituation, Stability
from dlovr.model.program import (
    ChatterRules,
    Detection,
    PoseTrack,
    TimedSituation,
    detections,
    motion_between,
    remove_chatter,
)
from dlovr.model.smoothing import made_by_hand
from dlovr.model.tracks import EdgeTrack, representative, stretch
from dlovr.model.transitions import CLASS_ORDER, classify_step, principal, successional_contacts
from dlovr.transforms import norm

NETWORK_VERSION = 1
"""Version of the network JSON format (``version`` field); bump on incompatible changes."""

Vec3 = tuple[float, float, float]
T = TypeVar("T")
RISKS = ("none", "caution", "risky")


class NetworkError(InputError):
    """A problem with the demonstrations or a network file; the message is one line."""


def edge_risk(classes: Sequence[str]) -> str:
    """Risk of a transition with these classes: ``risky`` (``I``, ``S``), ``caution`` (``T``) or ``none``."""
    if {"I", "S"} & set(classes):
        return "risky"
    if "T" in classes:
        return "caution"
    return "none"


def _r(x: float) -> float:
    return round(float(x), 9) + 0.0


def _vec(a: Sequence[float] | np.ndarray) -> Vec3:
    return (_r(a[0]), _r(a[1]), _r(a[2]))


# --------------------------------------------------------------------------------------------------
# Values
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Demonstration:
    """One demonstration: its kept situations (in time order) and gripper pose track, the scene it was
    made in (name and content hash; demonstrations of one network must share the hash), and the
    sensed gripper wrench when the recording has one (for the edges' detection parameters)."""

    name: str
    states: tuple[TimedSituation, ...]
    poses: PoseTrack
    scene_name: str = ""
    scene_sha256: str = ""
    wrench: WrenchSeries | None = None
    commands: PoseTrack | None = None  # the commanded gripper track, for the edges' own tracks
    program_run: bool = False  # a recorded run of a program: the executor moved, not a hand (by_hand)


@dataclass(frozen=True)
class MotionStats:
    """The demonstrated gripper motions along one edge (world frame, m; rotation vector, rad).

    ``world_mean``/``world_std``: mean and per-axis population standard deviation of the displacement;
    ``relative_mean``: mean displacement in the gripper frame at the start; ``rotation_mean``: mean
    rotation vector from the start orientation (gripper frame); ``start_mean``/``end_mean``: mean
    gripper position when the source / the target was entered; ``start_spread``: RMS distance of the
    start positions from their mean.
    """

    world_mean: Vec3
    world_std: Vec3
    relative_mean: Vec3
    rotation_mean: Vec3
    start_mean: Vec3
    start_spread: float
    end_mean: Vec3


@dataclass(frozen=True)
class Node:
    """A discrete situation of the network. Times in s; ``vector`` unit or zero, world frame: the
    normalised sum of the principal contacts' vectors; ``sensed``: the contact vector the
    demonstrations' wrench showed while the situation held (:func:`sensed_vectors`; unit, zero for
    no contact force, None without a wrench), which weighs each contact by how hard it pushes."""

    id: str
    situation: str
    principal: tuple[str, ...]
    stability: str
    vector: Vec3 | None
    visits: int
    total_time: float
    mean_time: float
    sensed: Vec3 | None = None


@dataclass(frozen=True)
class Edge:
    """A demonstrated transition ``source -> target`` (node ids). ``probability`` = ``count`` / all
    departures from ``source``; ``durations`` (s) one per demonstrated occurrence, in input order;
    ``demonstrations`` the indices of the demonstrations that took it (with repeats); ``detection``:
    per class, the detection its macro ends with (parameters merged over the occurrences); ``track``:
    one occurrence's commanded gripper track, the reference demonstration's where it took the edge,
    else the representative one (:mod:`dlovr.model.tracks`; None when the demonstrations carry no
    commands)."""

    source: str
    target: str
    classes: tuple[str, ...]
    risk: str
    count: int
    probability: float
    durations: tuple[float, ...]
    motion: MotionStats
    demonstrations: tuple[int, ...]
    detection: tuple[Detection, ...] = ()
    track: EdgeTrack | None = None

    @property
    def id(self) -> str:
        return f"{self.source}->{self.target}"

    @property
    def label(self) -> str:
        return ",".join(self.classes) if self.classes else "-"


@dataclass(frozen=True)
class Endpoint:
    """A start or end node: how many demonstrations began (ended) there, and the mean gripper
    position (m, world) then, with the RMS spread of those positions (m)."""

    node: str
    count: int
    position: Vec3
    spread: float


@dataclass(frozen=True)
class Network:
    """A transition network (module docstring). Build it with :func:`build_network`."""

    scene_name: str
    scene_sha256: str
    demonstrations: tuple[str, ...]
    nodes: tuple[Node, ...]
    edges: tuple[Edge, ...]
    starts: tuple[Endpoint, ...]
    ends: tuple[Endpoint, ...]
    start: str
    goal: str
    version: int = NETWORK_VERSION
    reference: EdgeTrack | None = None  # the reference demonstration's whole commanded track
    chatter: str = ""  # "": the kept situations as recorded; else how each one's chatter was removed

    def node(self, node_id: str) -> Node:
        for n in self.nodes:
            if n.id == node_id:
                return n
        raise NetworkError(f"node {node_id} is not in the network")

    def locate(self, situation: DiscreteSituation | str) -> str | None:
        """The id of the node of this situation (notation or value), or None outside the network."""
        key = situation if isinstance(situation, str) else situation.format()
        return next((n.id for n in self.nodes if n.situation == key), None)

    def out_edges(self, node_id: str) -> tuple[Edge, ...]:
        return tuple(e for e in self.edges if e.source == node_id)

    def graph(self) -> nx.DiGraph:
        """The network as a networkx ``DiGraph``: node and edge attributes are the dataclasses'
        fields (``data=`` the dataclass itself)."""
        g = nx.DiGraph()
        for n in self.nodes:
            g.add_node(n.id, data=n, stability=n.stability, label=" ".join(n.principal) or "free")
        for e in self.edges:
            g.add_edge(e.source, e.target, data=e, probability=e.probability, risk=e.risk, count=e.count)
        return g

    def to_json(self) -> dict[str, Any]:
        return {
            "version": self.version,
            "kind": "transition-network",
            "scene_name": self.scene_name,
            "scene_sha256": self.scene_sha256,
            "demonstrations": list(self.demonstrations),
            "start": self.start,
            "goal": self.goal,
            "starts": [_endpoint_json(p) for p in self.starts],
            "ends": [_endpoint_json(p) for p in self.ends],
            **({} if self.reference is None else {"reference": self.reference.to_json()}),
            **({"chatter": self.chatter} if self.chatter else {}),
            "nodes": [
                {
                    "id": n.id,
                    "situation": n.situation,
                    "principal": list(n.principal),
                    "stability": n.stability,
                    "vector": None if n.vector is None else list(n.vector),
                    "visits": n.visits,
                    "total_time": n.total_time,
                    "mean_time": n.mean_time,
                    "sensed": None if n.sensed is None else list(n.sensed),
                }
                for n in self.nodes
            ],
            "edges": [
                {
                    "source": e.source,
                    "target": e.target,
                    "classes": list(e.classes),
                    "label": e.label,
                    "risk": e.risk,
                    "count": e.count,
                    "probability": e.probability,
                    "durations": list(e.durations),
                    "demonstrations": list(e.demonstrations),
                    "motion": {
                        k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(e.motion).items()
                    },
                    "detection": [asdict(d) for d in e.detection],
                    **({} if e.track is None else {"track": e.track.to_json()}),
                }
                for e in self.edges
            ],
        }

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=1, ensure_ascii=False) + "\n"

    @staticmethod
    def from_json(data: Mapping[str, Any]) -> Network:
        """Read a network written by :meth:`to_json`; raises :class:`NetworkError` on bad input."""
        if not isinstance(data, Mapping) or data.get("kind") != "transition-network":
            raise NetworkError("not a transition network (no \"kind\": \"transition-network\")")
        if data.get("version") != NETWORK_VERSION:
            raise NetworkError(
                f"transition network format {data.get('version')}, this dlovr reads {NETWORK_VERSION}"
            )
        nodes = tuple(_each(data, "nodes", _node_from_json))
        edges = tuple(_each(data, "edges", _edge_from_json))
        with _at(""):
            ref = data.get("reference")
            net = Network(
                str(data["scene_name"]), str(data["scene_sha256"]), tuple(map(str, data["demonstrations"])),
                nodes, edges, tuple(_each(data, "starts", _endpoint_from_json)),
                tuple(_each(data, "ends", _endpoint_from_json)), str(data["start"]), str(data["goal"]),
                NETWORK_VERSION, None if ref is None else EdgeTrack.from_json(ref),
                str(data.get("chatter", "")),
            )
        _check(net)
        return net

    @staticmethod
    def loads(text: str, source: str = "network text") -> Network:
        """A network from its JSON text (see :meth:`from_json`); ``source`` names the text in errors."""
        return Network.from_json(parse_json(text, source, NetworkError))


def load_network(path: str | Path) -> Network:
    """Read a network file (written by :meth:`Network.dumps`); every problem is one
    :class:`NetworkError` line, ``<file>: <problem>``."""
    data = read_json(path, NetworkError, "network file")
    try:
        return Network.from_json(data)
    except NetworkError as e:
        raise NetworkError(where_msg(path, "", str(e))) from None


def _endpoint_json(p: Endpoint) -> dict[str, Any]:
    return {"node": p.node, "count": p.count, "position": list(p.position), "spread": p.spread}



@contextmanager
def _at(where: str) -> Iterator[None]:
    """Turns a missing key or a value of the wrong kind met inside into one :class:`NetworkError`
    worded like every input's (``where.key: missing``, ``where: problem``)."""
    try:
        yield
    except NetworkError:
        raise  # already names where (an item of a list inside)
    except KeyError as e:
        key = e.args[0] if e.args else "?"
        raise NetworkError(f"{where}.{key}: missing" if where else f"{key}: missing") from None
    except (TypeError, ValueError, IndexError, AttributeError) as e:
        raise NetworkError(f"{where or 'network'}: {type(e).__name__}: {e}") from None


def _each(data: Mapping[str, Any], key: str, parse: Callable[[Any], T]) -> Iterator[T]:
    """``parse`` of every item of the list ``data[key]``, a bad item named ``key[i]``."""
    with _at(""):
        items = data[key]
    if not isinstance(items, list):
        raise NetworkError(f"{key}: must be a list, got {type(items).__name__}")
    for i, item in enumerate(items):
        with _at(f"{key}[{i}]"):
            yield parse(item)


def _node_from_json(n: Mapping[str, Any]) -> Node:
    return Node(
        str(n["id"]), str(n["situation"]), tuple(map(str, n["principal"])), str(n["stability"]),
        None if n["vector"] is None else _vec(n["vector"]), int(n["visits"]),
        float(n["total_time"]), float(n["mean_time"]),
        None if n.get("sensed") is None else _vec(n["sensed"]),
    )


def _edge_from_json(e: Mapping[str, Any]) -> Edge:
    return Edge(
        str(e["source"]), str(e["target"]), tuple(map(str, e["classes"])), str(e["risk"]),
        int(e["count"]), float(e["probability"]), tuple(map(float, e["durations"])),
        _motion_from_json(e["motion"]), tuple(map(int, e["demonstrations"])),
        tuple(_detection_from_json(d) for d in e.get("detection", ())),
        None if e.get("track") is None else EdgeTrack.from_json(e["track"]),
    )


def _endpoint_from_json(d: Mapping[str, Any]) -> Endpoint:
    return Endpoint(str(d["node"]), int(d["count"]), _vec(d["position"]), float(d["spread"]))


def _motion_from_json(d: Mapping[str, Any]) -> MotionStats:
    return MotionStats(
        _vec(d["world_mean"]), _vec(d["world_std"]), _vec(d["relative_mean"]), _vec(d["rotation_mean"]),
        _vec(d["start_mean"]), float(d["start_spread"]), _vec(d["end_mean"]),
    )


def _detection_from_json(d: Mapping[str, Any]) -> Detection:
    return Detection(
        str(d["cls"]), str(d["algorithm"]), {str(k): float(v) for k, v in d["params"].items()},
        {str(k): str(v) for k, v in d.get("derivation", {}).items()},
    )


def _derived(d: Detection, key: str) -> bool:
    return d.derivation.get(key, "").startswith("derived")


def merge_detections(per_occurrence: Sequence[Sequence[Detection]]) -> tuple[Detection, ...]:
    """One detection per class from those derived at each occurrence of an edge: each parameter the
    median over the occurrences whose parameter was derived from a signal (``derived: ...``), the
    first occurrence's default where none was."""
    if not per_occurrence:
        return ()
    out = []
    for k, first in enumerate(per_occurrence[0]):
        same = [occ[k] for occ in per_occurrence if len(occ) > k and occ[k].cls == first.cls]
        params: dict[str, float] = {}
        texts: dict[str, str] = {}
        for key in first.params:
            vals = [d.params[key] for d in same if key in d.params and _derived(d, key)]
            if vals:
                params[key] = round(float(np.median(vals)), 6)
                texts[key] = (
                    f"derived: median over {len(vals)} of {len(same)} demonstrations "
                    f"({min(vals):.3g} to {max(vals):.3g})"
                )
            else:
                params[key] = first.params[key]
                texts[key] = first.derivation.get(key, "default: the class keeps it")
        out.append(Detection(first.cls, first.algorithm, params, texts))
    return tuple(out)


def reference_detections(own: Sequence[Detection]) -> tuple[Detection, ...]:
    """The detections of an edge the reference demonstration took: its own occurrence's, as a program
    compiled from it has them (the macro follows its track there; a median over other demonstrations'
    wrenches, a person's trembling one among them, can leave no signal where the reference has a
    clean step), each derived parameter's text saying so."""
    mark = " (the reference demonstration's own: its macro follows its track)"
    return tuple(
        replace(d, derivation={k: _own(t, mark) for k, t in d.derivation.items()}) for d in own
    )


def _own(text: str, mark: str) -> str:
    return text + mark if text.startswith("derived") else text


def _check(net: Network) -> None:
    ids = [n.id for n in net.nodes]
    if len(set(ids)) != len(ids):
        raise NetworkError("bad transition network: duplicate node ids")
    known = set(ids)
    for e in net.edges:
        if e.source not in known or e.target not in known:
            raise NetworkError(f"bad transition network: edge {e.id} names an unknown node")
        if e.count < 1 or e.risk not in RISKS:
            raise NetworkError(f"bad transition network: edge {e.id} has a bad count or risk")
    if net.start not in known or net.goal not in known:
        raise NetworkError("bad transition network: start or goal is not a node")


# --------------------------------------------------------------------------------------------------
# Construction
# --------------------------------------------------------------------------------------------------


def principal_contacts(situation: DiscreteSituation) -> tuple[DiscreteContact, ...]:
    """The principal contacts of all successional contacts of a situation, each distinct one once."""
    out: list[DiscreteContact] = []
    for run in successional_contacts(situation):
        for c in principal(run):
            if c not in out:
                out.append(c)
    return tuple(out)


def situation_stability(situation: DiscreteSituation) -> str:
    """``free`` (no principal contact), else the least stable principal contact's stability."""
    found = {c.state.stability_class for c in principal_contacts(situation)}
    if not principal_contacts(situation):
        return "free"
    if Stability.INSTABLE in found:
        return "instable"
    if Stability.SEMI in found:
        return "semi-stable"
    return "stable"


def situation_vector(situation: DiscreteSituation) -> np.ndarray | None:
    """Expected contact vector of a situation: the normalised sum of its principal contacts' vectors
    (world frame); zero when it has none or they cancel; None when one lacks its vector."""
    pcs = principal_contacts(situation)
    if any(c.vector is None for c in pcs):
        return None
    s = np.zeros(3)
    for c in pcs:
        s = s + np.asarray(c.vector, float)
    n = norm(s)
    return s / n if n > 1e-9 else np.zeros(3)


def _spread(points: np.ndarray) -> float:
    d = points - points.mean(axis=0)
    return _r(float(np.sqrt(np.mean(np.sum(d * d, axis=1)))))


def _check_scenes(demos: Sequence[Demonstration]) -> None:
    first = demos[0]
    for d in demos[1:]:
        if d.scene_sha256 != first.scene_sha256 or d.scene_name != first.scene_name:
            raise NetworkError(
                f"{d.name}: scene {d.scene_name or '?'} ({d.scene_sha256[:12] or 'no hash'}) differs from "
                f"{first.name}'s scene {first.scene_name or '?'} ({first.scene_sha256[:12] or 'no hash'}); "
                "a network merges demonstrations of one scene"
            )


def _most_common(counter: Counter[str], order: Sequence[str]) -> str:
    best = max(counter.values())
    return next(k for k in order if counter.get(k) == best)


#: One occurrence of an edge: (demonstration index, duration s, gripper motion, gripper position at
#: its start and at its end, whether it went through free space).
_Occurrence = tuple[int, float, Any, np.ndarray, np.ndarray, bool]
#: One occurrence's two timed situations and its demonstration's wrench.
_StepPair = tuple[TimedSituation, TimedSituation, WrenchSeries | None]


@dataclass
class _Visits:
    """What the demonstrations visited, gathered by :func:`_visit`: node ids by situation key
    (``ids``, in order of first visit), the situations, per node id the times held and the contact
    vectors, per edge (node id pair) its occurrences and their steps, each demonstration's first and
    last node with the gripper position there, and per demonstration the node id of each state."""

    ids: dict[str, str] = field(default_factory=dict)
    sits: dict[str, DiscreteSituation] = field(default_factory=dict)
    held: dict[str, list[float]] = field(default_factory=dict)
    vectors: dict[str, list[np.ndarray]] = field(default_factory=dict)
    occ: dict[tuple[str, str], list[_Occurrence]] = field(default_factory=dict)
    steps: dict[tuple[str, str], list[_StepPair]] = field(default_factory=dict)
    firsts: list[tuple[str, np.ndarray]] = field(default_factory=list)
    lasts: list[tuple[str, np.ndarray]] = field(default_factory=list)
    demo_keys: list[list[str]] = field(default_factory=list)


def build_network(
    demos: Sequence[Demonstration], chatter: ChatterRules | None = None, *, hands_only: bool = False
) -> Network:
    """Merge demonstrations of one scene into a transition network (module docstring).

    ``chatter``: merge each demonstration's path to its goal instead of its kept situations as they
    happened: its chatter removed first as a program's compiler removes it
    (:func:`dlovr.model.program.remove_chatter` with these rules; the network says so in ``chatter``);
    with ``hands_only``, only from the demonstrations a hand made (:func:`by_hand`): a script's flips
    are the scene's, not a hovering hand's, and stay."""
    if not demos:
        raise NetworkError("no demonstrations to build a network from")
    _check_scenes(demos)
    for d in demos:
        if not d.states:
            raise NetworkError(f"{d.name}: demonstration has no contact situations")
    cleaned = [chatter is not None and (not hands_only or by_hand(d)) for d in demos]
    if chatter is not None:
        demos = [replace(d, states=tuple(remove_chatter(d.states, d.poses, chatter))) if c else d
                 for d, c in zip(demos, cleaned, strict=True)]
    seen = _Visits()
    for di, d in enumerate(demos):
        _visit(seen, di, d)
    sensed = sensed_vectors(demos, seen.demo_keys)
    reference = reference_demonstration(seen.demo_keys, list(seen.ids.values()))
    by_id = {v: k for k, v in seen.ids.items()}
    nodes = [_node(seen, by_id, nid, sensed) for nid in seen.ids.values()]
    edges = _edges(demos, seen, by_id, reference)
    firsts, lasts, order = seen.firsts, seen.lasts, list(seen.ids.values())
    net = Network(
        demos[0].scene_name, demos[0].scene_sha256, tuple(d.name for d in demos), tuple(nodes), tuple(edges),
        _endpoints(firsts, order), _endpoints(lasts, order),
        _most_common(Counter(k for k, _ in firsts), order), _most_common(Counter(k for k, _ in lasts), order),
        NETWORK_VERSION, _whole_track(demos[reference], reference),
        _chatter_note(chatter, sum(cleaned) if hands_only else None, len(demos)),
    )
    _check(net)
    return net


def _chatter_note(rules: ChatterRules | None, hands: int | None = None, n: int = 0) -> str:
    """What a network records of how its demonstrations' chatter was treated ("": kept); ``hands``:
    removed only from the demonstrations a hand made, this many of ``n``."""
    if rules is None or hands == 0:
        return ""
    which = "each demonstration" if hands is None else f"each demonstration made by a hand ({hands} of {n})"
    return (f"removed from {which} (an excursion back to where it left within {rules.max_s:g} s, "
            f"{rules.max_m:g} m and {rules.max_deg:g} deg of gripper motion)")


def by_hand(demo: Demonstration) -> bool:
    """Was ``demo`` made by a hand (:func:`dlovr.model.smoothing.made_by_hand` of its commanded
    track; True without one, as nothing tells it from a hand's)? A recorded program run is not: the
    executor's track accelerates where it registers, turns and holds, but no hand hovers there."""
    if demo.program_run:
        return False
    if demo.commands is None:
        return True
    return made_by_hand(demo.commands.t, demo.commands.pos)


def _visit(seen: _Visits, di: int, d: Demonstration) -> None:
    """Add demonstration ``d`` (index ``di``) to ``seen``: its states as nodes, its steps as edge
    occurrences."""
    keys: list[str] = []
    seen.demo_keys.append(keys)
    for s in d.states:
        key = s.situation.format()
        if key not in seen.ids:
            seen.ids[key] = f"n{len(seen.ids) + 1}"
            seen.sits[key] = s.situation
        keys.append(seen.ids[key])
        seen.held.setdefault(seen.ids[key], []).append(s.duration)
        v = situation_vector(s.situation)
        if v is not None:
            seen.vectors.setdefault(seen.ids[key], []).append(v)
    seen.firsts.append((keys[0], d.poses.at(d.states[0].t)[0]))
    end = d.states[-1]
    seen.lasts.append((keys[-1], d.poses.at(end.t + end.duration)[0]))
    for k in range(1, len(d.states)):
        a, b = d.states[k - 1], d.states[k]
        mv = motion_between(d.poses, a.t, b.t)
        seen.occ.setdefault((keys[k - 1], keys[k]), []).append(
            (di, b.t - a.t, mv, d.poses.at(a.t)[0], d.poses.at(b.t)[0], bool(b.through_free))
        )
        seen.steps.setdefault((keys[k - 1], keys[k]), []).append((a, b, d.wrench))


def _node(seen: _Visits, by_id: Mapping[str, str], nid: str, sensed: Mapping[str, Vec3]) -> Node:
    """The node ``nid``: its situation's principal contacts and stability, mean contact vector,
    visits and times held."""
    sit = seen.sits[by_id[nid]]
    vs = seen.vectors.get(nid)
    vec = None
    if vs:
        m = np.mean(vs, axis=0)
        n = norm(m)
        vec = _vec(m / n if n > 1e-9 else np.zeros(3))
    h = seen.held[nid]
    return Node(nid, by_id[nid], tuple(c.format() for c in principal_contacts(sit)),
                situation_stability(sit), vec, len(h), _r(sum(h)), _r(sum(h) / len(h)), sensed.get(nid))


def _edges(
    demos: Sequence[Demonstration], seen: _Visits, by_id: Mapping[str, str], reference: int
) -> list[Edge]:
    """The edges, ordered by node number: classes, risk, probability, durations, motion statistics,
    merged detections and track."""
    departures = Counter[str]()
    for (u, _), xs in seen.occ.items():
        departures[u] += len(xs)
    edges = []
    for (u, v), xs in sorted(seen.occ.items(), key=lambda kv: (int(kv[0][0][1:]), int(kv[0][1][1:]))):
        # a flight (through free space) is S,E where a direct step is S: an edge taken both ways has both
        flights = sorted({x[5] for x in xs})
        union = {c for f in flights for c in classify_step(seen.sits[by_id[u]], seen.sits[by_id[v]], f)}
        classes = tuple(c for c in CLASS_ORDER if c in union)
        motion = _motion_stats(xs)
        steps = seen.steps[(u, v)]
        per = [detections(classes, a, b, w, None) for a, b, w in steps]
        mine = [k for k, x in enumerate(xs) if x[0] == reference]
        derived = reference_detections(per[mine[0]]) if mine else merge_detections(per)
        edges.append(
            Edge(u, v, classes, edge_risk(classes), len(xs), _r(len(xs) / departures[u]),
                 tuple(_r(x[1]) for x in xs), motion, tuple(x[0] for x in xs), derived,
                 _edge_track(demos, xs, steps, reference))
        )
    return edges


def _motion_stats(xs: Sequence[_Occurrence]) -> MotionStats:
    """The gripper motion of an edge's occurrences ``xs``: mean and spread of the displacement, mean
    relative motion and rotation, mean and spread of the start points, mean end point."""
    world = np.array([x[2].world for x in xs])
    starts, ends = np.array([x[3] for x in xs]), np.array([x[4] for x in xs])
    return MotionStats(
        _vec(world.mean(axis=0)), _vec(world.std(axis=0)),
        _vec(np.mean([x[2].relative for x in xs], axis=0)),
        _vec(np.mean([x[2].rotation for x in xs], axis=0)),
        _vec(starts.mean(axis=0)), _spread(starts), _vec(ends.mean(axis=0)),
    )


def reference_demonstration(demo_keys: Sequence[Sequence[str]], order: Sequence[str]) -> int:
    """The demonstration whose tracks the network's macros follow where they can: the first one given
    that ended in the goal (the most common last situation). Its tracks were made with one cable in
    one scene, so they join without mixing them; give the demonstration you trust most first."""
    goal = _most_common(Counter(k[-1] for k in demo_keys), order)
    return next(i for i, k in enumerate(demo_keys) if k[-1] == goal)


def _whole_track(demo: Demonstration, index: int) -> EdgeTrack | None:
    """The demonstration's whole commanded track (None without commands): network macros along its
    path follow it as a compiled program follows its demonstration."""
    c = demo.commands
    return None if c is None else stretch(c, index, float(c.t[0]), float(c.t[-1]))


def _edge_track(
    demos: Sequence[Demonstration], xs: Sequence[Any], steps: Sequence[Any], reference: int = -1
) -> EdgeTrack | None:
    """The edge's track (:mod:`dlovr.model.tracks`): the reference demonstration's first occurrence
    when it took the edge, else the representative occurrence among those whose demonstration has
    commands."""
    have = [k for k, x in enumerate(xs) if demos[x[0]].commands is not None]
    if not have:
        return None
    mine = [k for k in have if xs[k][0] == reference]
    k = mine[0] if mine else have[representative([xs[i][2].world for i in have])]
    a, b, _ = steps[k]
    return stretch(demos[xs[k][0]].commands, xs[k][0], a.t, b.t)


#: When a run senses the situation a transition led to, after entering it (s): its detectors fire
#: about this late (the step's rise to its threshold and the filters; 38-46 ms on the peg-in-hole
#: reference, 42 ms median over trials), then it holds :data:`SENSE_HOLD_S` and senses
#: (``dlovr.execution.network_run``). A node's sensed vector is taken over the same window.
SENSE_DELAY_S = 0.04
#: How long (s) a run holds still after a detection before it senses the contact vector.
SENSE_HOLD_S = 0.05


def sensed_vectors(
    demos: Sequence[Demonstration],
    node_ids: Sequence[Sequence[str]],
    delay: float = SENSE_DELAY_S,
    hold: float = SENSE_HOLD_S,
    floor: float = 0.02,
) -> dict[str, Vec3]:
    """Per node id, the contact vector the demonstrations sensed where a run senses it: in each
    occurrence, over the window a run senses in after entering it (from ``delay`` s, the detection's
    latency, for ``hold`` s, the sensing hold; from half its stay when it held less than ``delay``,
    to its end when less than ``delay + hold``; the first situation, entered by no transition: its
    stay after 50 ms), ``-(mean force - tare)`` with the tare the mean force
    in the demonstration's first situation (after its first 50 ms) when that one touches nothing (the
    cable's weight), unit, or zero under ``floor`` N; the occurrences' mean, normalised (zero when
    most were zero). A node's force may change over a long stay (a drag pushes harder and tilts it):
    the vector a run can compare with is the one just after the transition, not the stay's mean.
    ``node_ids``: per
    demonstration, the node id of each of its states. Demonstrations without a wrench, or not
    starting in free space, give none."""
    per: dict[str, list[np.ndarray]] = {}
    for d, nids in zip(demos, node_ids, strict=True):
        w = d.wrench
        if w is None or not d.states or situation_stability(d.states[0].situation) != "free":
            continue
        first = d.states[0]
        base = w.window(first.t + 0.05, first.t + first.duration)  # after its first 50 ms
        if len(base) < 3:
            continue
        tare = base.mean(axis=0)
        for i, (s, nid) in enumerate(zip(d.states, nids, strict=True)):
            # the first situation was entered by no transition (the recording's start, still settling)
            a, b = s.t + min(delay, 0.5 * s.duration), s.t + min(delay + hold, s.duration)
            f = base if i == 0 else w.window(a, b)
            if len(f) == 0:  # held shorter than the wrench's sampling period
                continue
            v = -(f.mean(axis=0) - tare)
            n = norm(v)
            per.setdefault(nid, []).append(v / n if n >= floor else np.zeros(3))
    out = {}
    for nid, vs in per.items():
        zeros = sum(1 for v in vs if not v.any())
        m = np.mean([v for v in vs if v.any()] or [np.zeros(3)], axis=0)
        n = norm(m)
        out[nid] = _vec(np.zeros(3) if zeros * 2 > len(vs) or n < 1e-9 else m / n)
    return out


def _endpoints(items: Sequence[tuple[str, np.ndarray]], order: Sequence[str]) -> tuple[Endpoint, ...]:
    out = []
    for nid in order:
        pts = np.array([p for k, p in items if k == nid])
        if len(pts):
            out.append(Endpoint(nid, len(pts), _vec(pts.mean(axis=0)), _spread(pts)))
    return tuple(out)
