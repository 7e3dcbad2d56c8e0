"""Network programs: choosing, at every node of a transition network, the macro toward the goal
(paper §VI: "a probabilistic control mechanism is needed due to the stochastic behaviour of the contact
state transitions"). Pure Python + numpy; the rules in words are in docs/networks.md.

**Where the gripper is matters.** One discrete situation can be visited at very different gripper poses
(free space at the start and again after the DLO snapped off an edge), and what follows it depends on
where the gripper is. So a departure is planned from a *context*: a node and the gripper position
``x`` (m, world frame) there.

- **Applicable departures** at ``(u, x)``: the out-edges ``e`` of ``u`` whose demonstrated start
  position ``s(e)`` is near ``x``. With ``d(e) = max(0, |x - s(e)| - 2 spread(e))``, those with
  ``d(e) <= min_e d(e) + reach`` (``reach`` default 0.02 m); with ``x`` unknown, all out-edges. The
  reference demonstration's own departures from ``u`` (:func:`reference_path`) are applicable
  wherever the gripper is: a run follows the reference's track from wherever it got to, as a
  compiled program does (a 9 % longer cable holds the gripper 2-3 cm above the reference's
  positions all the way, and the other demonstrations' departures there led nowhere).
- **Departure probability** ``p(e | u, x) = count(e) / sum of count(e')`` over the applicable ``e'``
  (with ``x`` unknown this is the edge's probability in the network).
- After ``e`` the gripper is at ``e``'s mean end position, the context of the next choice.
- **Blind departures** (:func:`blind`: a deliberate transition whose detections have no force signal,
  which a run takes to have happened without sensing) may be chosen only where they are the most
  frequent applicable departure (:meth:`NetworkProgram.plannable`); they stay outcomes.
- **Best path** from a context to the goal node: the path ``e1 … ek`` that maximises ``P``, the product
  of the departure probabilities along it (exact fractions); among equal ``P`` the one with fewer risky
  edges (``I``, ``S``), then fewer caution edges (``T``), then fewer edges, then the smallest edge ids.
  It is found by a label-setting (Dijkstra) search backwards from the goal over arrival states (one per
  edge): extending a path never raises ``P`` and always adds an edge, and prefixing an edge (``p > 0``)
  keeps the order of two paths, so the first label settled for a state is its best.
- **Macro**: the edges of the best path from the first up to and including the first one that has a
  transition class (a ``-`` step changes no principal contact, so nothing could detect it; its motion
  joins the next macro's, as in :func:`dlovr.model.program.compile_program`); when no classed edge
  remains, a final macro that moves to the goal without detection.
- **Successors**: the nodes the macro's first detected transition can lead to, with probabilities: the
  targets of the applicable classed edges, and through applicable ``-`` edges where a walk on through
  ``-`` edges lands (round a ``-`` cycle as often as it goes; :meth:`NetworkProgram._walks`; the
  probabilities are normalised to sum 1). After a detection the executor
  identifies the node reached with :func:`identify` from the sensed contact vector and calls
  :meth:`NetworkProgram.replan` there.
"""

from __future__ import annotations

import heapq
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any, cast

import numpy as np

from dlovr.inputs import read_json, where_msg
from dlovr.model.detection import MIN_SNR, no_force_signal
from dlovr.model.network import RISKS, Edge, Network, NetworkError, Vec3
from dlovr.model.program import Detection, Program, ProgramError
from dlovr.transforms import norm

PROGRAM_VERSION = 1
"""Version of the network-program JSON format."""

DEFAULT_REACH_M = 0.02
"""How far (m) beyond the nearest demonstrated start a departure still counts as applicable."""

_Key = tuple[Fraction, int, int, int]  # P, risky, caution, length


@dataclass(frozen=True)
class Successor:
    """A node the next detected transition may lead to, its expected contact vector (unit or zero,
    world frame: the one the demonstrations sensed there, else the sum of its principal contacts')
    and the probability of reaching it first."""

    node: str
    situation: str
    principal: tuple[str, ...]
    vector: Vec3 | None
    probability: float


@dataclass(frozen=True)
class MacroPlan:
    """One macro of a network program: the network edges it follows (ids), the classes of the
    transition that ends it and its risk, the node expected after it, whether it is the final macro
    (no detection), and its motion: summed mean world displacement (m), root-sum-square of the
    per-axis spreads (m), summed mean rotation vector (rad, gripper frame) and mean duration (s); the
    detection of each class of its last edge (parameters derived from the demonstrations)."""

    edges: tuple[str, ...]
    classes: tuple[str, ...]
    risk: str
    target: str
    final: bool
    world: Vec3
    world_std: Vec3
    rotation: Vec3
    duration: float
    detection: tuple[Detection, ...] = ()


@dataclass(frozen=True)
class Choice:
    """The plan from one context: the first edge, its departure probability, the best path's
    probability of reaching the goal and its risky/caution/length counts, its nodes, the macro to run
    now, and the possible successors of that macro."""

    node: str
    position: Vec3 | None
    edge: str
    probability: float
    reach_probability: float
    risky: int
    caution: int
    length: int
    path: tuple[str, ...]
    macro: MacroPlan
    successors: tuple[Successor, ...]


@dataclass(frozen=True)
class Context:
    """A node with how it was reached (``start``, an edge id, or ``any`` when the pose is unknown),
    the gripper position then (m, world) and the choice there (None at the goal or without a path)."""

    node: str
    arrived_by: str
    position: Vec3 | None
    choice: Choice | None


def _r(x: float | Fraction) -> float:
    return round(float(x), 9) + 0.0


def _dist(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    return math.sqrt(sum((float(x) - float(y)) ** 2 for x, y in zip(a, b, strict=True)))


def departure_distance(e: Edge, position: Sequence[float] | np.ndarray) -> float:
    """How far (m) the gripper at ``position`` (world) is from where the demonstrations set off along
    ``e``: ``max(0, |x - s(e)| - 2 spread(e))``, ``s(e)`` the mean gripper position where they
    entered its source (:meth:`NetworkProgram.applicable` keeps the departures within ``reach`` of
    the nearest)."""
    return max(0.0, _dist(position, e.motion.start_mean) - 2.0 * e.motion.start_spread)


def _counts(e: Edge) -> tuple[int, int]:
    return int(e.risk == "risky"), int(e.risk == "caution")


def expected_vector(node: Any) -> Vec3 | None:
    """The contact vector a node is identified by: the one its demonstrations sensed, else the sum
    of its principal contacts' vectors (docs/networks.md)."""
    return node.sensed if node.sensed is not None else node.vector


def identify(
    successors: Sequence[Successor],
    sensed_vector: Sequence[float] | np.ndarray | None,
    tolerance: float | None = None,
    sigma: float | None = None,
) -> Successor | None:
    """The successor the sensed contact vector shows.

    ``sensed_vector`` (world frame, the convention of eq. 2) is normalised; ``None`` or a vector
    shorter than 1e-9 means no contact (the zero vector). Without ``sigma``: the successor whose
    expected vector is closest (Euclidean); ties go to the more probable successor, then the smaller
    node id. With ``sigma`` (the spread of sensed vectors, a distance between unit vectors): the most
    probable one given the sensed vector, ``probability * exp(-d^2 / (2 sigma^2))`` (its probability
    as the prior, a Gaussian in the distance ``d`` as the likelihood; ties to the smaller node id), so
    that a likely successor a little farther away wins over an unlikely one that happens to be nearer.
    Successors without a vector are skipped. Returns None when none has a vector or (with
    ``tolerance``) when the closest is farther than ``tolerance``: a situation outside the network.
    """
    s = np.zeros(3) if sensed_vector is None else np.asarray(sensed_vector, float).reshape(3)
    n = norm(s)
    s = s / n if n > 1e-9 else np.zeros(3)
    scored = [(_dist(s, c.vector), c) for c in successors if c.vector is not None]
    if not scored:
        return None
    nearest = min(scored, key=lambda x: (x[0], -x[1].probability, x[1].node))
    if tolerance is not None and nearest[0] > tolerance:
        return None
    if sigma is None:
        return nearest[1]
    if tolerance is not None:
        scored = [x for x in scored if x[0] <= tolerance]

    def posterior(x: tuple[float, Successor]) -> tuple[float, int]:
        d, c = x
        num = int(c.node[1:]) if c.node[1:].isdigit() else 0
        return c.probability * math.exp(-(d**2) / (2.0 * sigma**2)), -num

    return max(scored, key=posterior)[1]


class NetworkProgram:
    """A network program: the planner over one network (module docstring) and its JSON form; like a
    compiled :class:`dlovr.model.program_format.Program` it is a
    :class:`~dlovr.model.program_format.Runnable` that the execution engine takes."""

    def __init__(self, network: Network, reach: float = DEFAULT_REACH_M, name: str = "", source: str = ""):
        if not reach >= 0:
            raise NetworkError(f"reach must be >= 0 m, got {reach}")
        self.network, self.reach, self.name, self.source = network, float(reach), name, source
        self._edges = {e.id: e for e in network.edges}
        self._out: dict[str, tuple[Edge, ...]] = {n.id: network.out_edges(n.id) for n in network.nodes}
        self._nodes = {n.id: n for n in network.nodes}
        self._terminal = {e.id for e in network.edges if e.target == network.goal}
        self._blind = {e.id for e in network.edges if blind(e)}
        self._reference = frozenset(reference_path(network))
        #: caches (the network does not change): applicable departures per context, and where a walk
        #: on through ``-`` edges after each ``-`` edge lands (:meth:`_walks`, made when first needed)
        self._applicable: dict[tuple[str, tuple[float, ...] | None], tuple[Edge, ...]] = {}
        self._walk: dict[str, dict[str, Fraction]] | None = None
        self._value, self._next = self._solve()

    # ---------------------------------------------------------------------------------------------
    # Planning
    # ---------------------------------------------------------------------------------------------

    def applicable(self, node: str, position: Sequence[float] | None) -> tuple[Edge, ...]:
        """Departures from ``node`` applicable with the gripper at ``position`` (module docstring):
        those near it, and the reference demonstration's own wherever it is."""
        key = (node, None if position is None else tuple(float(x) for x in position))
        found = self._applicable.get(key)
        if found is not None:
            return found
        es = self._out[node]
        if position is not None and es:
            d = [departure_distance(e, position) for e in es]
            limit = min(d) + self.reach
            es = tuple(e for e, di in zip(es, d, strict=True) if di <= limit or e.id in self._reference)
        self._applicable[key] = es
        return es

    def plannable(self, opts: Sequence[Edge]) -> tuple[Edge, ...]:
        """The applicable departures ``opts`` a plan may choose: all but a :func:`blind` one that is
        not the most frequent of them. The executor takes a blind macro to have made its transition
        without sensing (docs/networks.md), so a plan bets only on what the motion made most often
        there, never on a rarer outcome that no sensing would correct."""
        most = max((o.count for o in opts), default=0)
        return tuple(o for o in opts if o.id not in self._blind or o.count == most)

    def _solve(self) -> tuple[dict[str, _Key], dict[str, str | None]]:
        pred: dict[str, list[tuple[str, Fraction]]] = {}
        for e1 in self.network.edges:
            if e1.id in self._terminal:
                continue
            opts = self.applicable(e1.target, e1.motion.end_mean)
            total = sum(o.count for o in opts)
            for e2 in self.plannable(opts):
                pred.setdefault(e2.id, []).append((e1.id, Fraction(e2.count, total)))
        value: dict[str, _Key] = {}
        nxt: dict[str, str | None] = {}
        heap: list[tuple[tuple[Fraction, int, int, int], str, str]] = [
            ((Fraction(-1), 0, 0, 0), eid, "") for eid in sorted(self._terminal)
        ]
        heapq.heapify(heap)
        while heap:
            (negp, r, c, n), eid, via = heapq.heappop(heap)
            if eid in value:
                continue
            value[eid], nxt[eid] = (-negp, r, c, n), via or None
            e2 = self._edges[eid]
            dr, dc = _counts(e2)
            for e1id, p in pred.get(eid, ()):
                if e1id not in value:
                    heapq.heappush(heap, ((-(p * -negp), r + dr, c + dc, n + 1), e1id, eid))
        return value, nxt

    def replan(self, node: str, position: Sequence[float] | None = None) -> Choice | None:
        """The choice at ``node`` with the gripper at ``position`` (m, world; None: unknown): what the
        executor runs after identifying the node it reached. None at the goal or when no demonstrated
        path leads from there to the goal; :class:`NetworkError` for a node outside the network."""
        if node not in self._out:
            raise NetworkError(f"node {node} is not in the network: the situation was never demonstrated")
        if node == self.network.goal:
            return None
        opts = self.applicable(node, position)
        total = sum(e.count for e in opts)
        best: tuple[Fraction, int, int, int, str] | None = None
        for e in self.plannable(opts):
            v = self._value.get(e.id)
            if v is None:
                continue
            dr, dc = _counts(e)
            key = (-(Fraction(e.count, total) * v[0]), v[1] + dr, v[2] + dc, v[3] + 1, e.id)
            best = key if best is None or key < best else best
        if best is None:
            return None
        negp, risky, caution, length, eid = best
        chain = [eid]
        while (nx := self._next[chain[-1]]) is not None:
            chain.append(nx)
        pos = None if position is None else cast(Vec3, tuple(_r(x) for x in position))
        return Choice(
            node, pos, eid, _r(Fraction(self._edges[eid].count, total)), _r(-negp), risky, caution, length,
            (node, *(self._edges[c].target for c in chain)), self._macro(chain),
            self._successors(node, position),
        )

    def _macro(self, chain: Sequence[str]) -> MacroPlan:
        edges: list[Edge] = []
        for eid in chain:
            edges.append(self._edges[eid])
            if edges[-1].classes:
                break
        last = edges[-1]
        ms = [e.motion for e in edges]
        world = np.sum([m.world_mean for m in ms], axis=0)
        std = np.sqrt(np.sum(np.square([m.world_std for m in ms]), axis=0))
        rot = np.sum([m.rotation_mean for m in ms], axis=0)
        duration = sum(sum(e.durations) / len(e.durations) for e in edges)
        return MacroPlan(
            tuple(e.id for e in edges), last.classes, max((e.risk for e in edges), key=RISKS.index),
            last.target, not last.classes, cast(Vec3, tuple(map(_r, world))), cast(Vec3, tuple(map(_r, std))),
            cast(Vec3, tuple(map(_r, rot))), _r(duration), last.detection,
        )

    def _passes(self, e: Edge) -> bool:
        """Whether ``e`` is a ``-`` step that :meth:`_outcomes` follows on (no class, not into the goal)."""
        return not e.classes and e.target != self.network.goal

    def _walks(self) -> dict[str, dict[str, Fraction]]:
        """For every ``-`` edge ``u`` (:meth:`_passes`): the nodes a walk on from ``u``'s end lands in
        and their probabilities ``x_u``. The walk takes the departures applicable at each ``-`` edge's
        end with their probabilities; a classed one (or one into the goal) lands at its target, a
        ``-`` one walks on: ``x_u = sum_o p(o) (x_o if o is a - edge else [target(o)])``, solved
        exactly (fractions; Gauss-Jordan on ``I - P``, which is regular once the edges that can never
        land are left out: their walks, a ``-`` cycle without a way out, land nowhere). In a network
        without ``-`` cycles this is the sum over the paths through ``-`` edges; with them a walk
        may go round a cycle before it leaves it (counting each path that uses an edge at most once
        instead grows exponentially with the network, minutes for fifty situations)."""
        if self._walk is not None:
            return self._walk
        steps = {
            e.id: self.applicable(e.target, e.motion.end_mean) for e in self.network.edges if self._passes(e)
        }
        live = {u for u, opts in steps.items() if any(not self._passes(o) for o in opts)}
        grew = True
        while grew:
            grew = False
            for u, opts in steps.items():
                if u not in live and any(o.id in live for o in opts):
                    live.add(u)
                    grew = True
        order = sorted(live)
        rows: dict[str, dict[str, Fraction]] = {}
        rhs: dict[str, dict[str, Fraction]] = {}
        for u in order:
            total = sum(o.count for o in steps[u])
            row, b = {u: Fraction(1)}, {}
            for o in steps[u]:
                p = Fraction(o.count, total)
                if not self._passes(o):
                    b[o.target] = b.get(o.target, Fraction(0)) + p
                elif o.id in live:
                    row[o.id] = row.get(o.id, Fraction(0)) - p
            rows[u], rhs[u] = row, b
        for v in order:
            _eliminate(v, rows, rhs)
        self._walk = {u: rhs[u] for u in order}
        return self._walk

    def _outcomes(self, node: str, position: Sequence[float] | None) -> dict[str, Fraction]:
        """Where a macro from ``(node, position)`` lands: the targets of the applicable classed edges
        (and of those into the goal), and through the applicable ``-`` edges where their walks land
        (:meth:`_walks`), with their probabilities."""
        opts = self.applicable(node, position)
        total = sum(e.count for e in opts)
        walks = self._walks() if any(self._passes(e) for e in opts) else {}
        out: dict[str, Fraction] = {}
        for e in opts:
            p = Fraction(e.count, total)
            if not self._passes(e):
                out[e.target] = out.get(e.target, Fraction(0)) + p
            else:
                for k, q in walks.get(e.id, {}).items():
                    out[k] = out.get(k, Fraction(0)) + p * q
        return out

    def _successors(self, node: str, position: Sequence[float] | None) -> tuple[Successor, ...]:
        out = self._outcomes(node, position)
        total = sum(out.values()) or Fraction(1)
        rows = sorted(out.items(), key=lambda kv: (-kv[1], int(kv[0][1:])))
        nodes = self._nodes
        return tuple(
            Successor(k, nodes[k].situation, nodes[k].principal, expected_vector(nodes[k]), _r(p / total))
            for k, p in rows
        )

    def contexts(self, node: str) -> tuple[Context, ...]:
        """The precomputed contexts of a node: each start there, each arrival edge, and ``any``."""
        ctx = [Context(node, "start", p.position, None) for p in self.network.starts if p.node == node]
        ctx += [Context(node, e.id, e.motion.end_mean, None) for e in self.network.edges if e.target == node]
        ctx.append(Context(node, "any", None, None))
        return tuple(Context(c.node, c.arrived_by, c.position, self.replan(node, c.position)) for c in ctx)

    def plan_from_start(self, max_macros: int = 1000) -> list[Choice]:
        """The expected run: the choices from the most common start, following each macro's target."""
        net = self.network
        start = next(p for p in net.starts if p.node == net.start)
        node, pos, out = net.start, start.position, []
        while len(out) < max_macros and (ch := self.replan(node, pos)) is not None:
            out.append(ch)
            node, pos = ch.macro.target, self._edges[ch.macro.edges[-1]].motion.end_mean
        return out

    def path_probability(self, edges: Sequence[str], position: Sequence[float] | None = None) -> float:
        """The probability the planner gives a path (edge ids) from the start of its first edge with
        the gripper at ``position`` (m, world; None: unknown): the product of its departure
        probabilities, each edge's context the previous one's mean end position (module docstring). 0
        when an edge is not applicable where the path reaches its source. The best path from a context
        never has a smaller one (what ``bench_network.py`` checks against :func:`reference_path`)."""
        p, pos = Fraction(1), None if position is None else tuple(float(x) for x in position)
        for eid in edges:
            e = self._edges[eid]
            opts = self.applicable(e.source, pos)
            if all(o.id != eid for o in opts):
                return 0.0
            p *= Fraction(e.count, sum(o.count for o in opts))
            pos = e.motion.end_mean
        return _r(p)

    # ---------------------------------------------------------------------------------------------
    # JSON and text
    # ---------------------------------------------------------------------------------------------

    def to_json(self) -> dict[str, Any]:
        net = self.network
        plan = self.plan_from_start()
        return {
            "version": PROGRAM_VERSION,
            "kind": "network-program",
            "name": self.name,
            "source": self.source,
            "reach_m": self.reach,
            "scene_name": net.scene_name,
            "scene_sha256": net.scene_sha256,
            "start": net.start,
            "goal": net.goal,
            "summary": {
                "nodes": len(net.nodes),
                "edges": len(net.edges),
                "plan_macros": len(plan),
                "plan_reach_probability": (
                    plan[0].reach_probability if plan else float(net.start == net.goal)
                ),
                "plan_risky": sum(ch.macro.risk == "risky" for ch in plan),
            },
            "plan": [asdict(ch) for ch in plan],
            "nodes": [
                {
                    "node": n.id,
                    "situation": n.situation,
                    "stability": n.stability,
                    "goal": n.id == net.goal,
                    "contexts": [asdict(c) for c in self.contexts(n.id)],
                }
                for n in net.nodes
            ],
            "network": net.to_json(),
        }

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=1, ensure_ascii=False) + "\n"

    @staticmethod
    def from_json(data: Mapping[str, Any]) -> NetworkProgram:
        if not isinstance(data, Mapping) or data.get("kind") != "network-program":
            raise NetworkError('not a network program (no "kind": "network-program")')
        if data.get("version") != PROGRAM_VERSION:
            raise NetworkError(
                f"network program format {data.get('version')}, this dlovr reads {PROGRAM_VERSION}"
            )
        try:
            reach, name, source = float(data["reach_m"]), str(data["name"]), str(data["source"])
            net = data["network"]
        except KeyError as e:  # a key's name, never Python's "KeyError: 'reach_m'"
            raise NetworkError(f"{e.args[0] if e.args else '?'}: missing") from None
        except (TypeError, ValueError) as e:
            raise NetworkError(f"reach_m: not a number: {str(e)[:80]}") from None
        return NetworkProgram(Network.from_json(net), reach, name, source)

    def listing(self) -> str:
        """A readable text listing: the plan from the start, then the choice at every node."""
        net = self.network
        lines = [
            f"network program {self.name}  (from {self.source}; "
            f"{len(net.nodes)} nodes, {len(net.edges)} edges)"
        ]
        lines.append(f"start {net.start}, goal {net.goal}: {net.node(net.goal).situation}")
        for i, ch in enumerate(self.plan_from_start(), 1):
            m = ch.macro
            label = "final" if m.final else ",".join(m.classes)
            lines.append(
                f"{i:>3}  {ch.node} -> {m.target}  {label:<5} risk {m.risk:<7} "
                f"P(goal)={ch.reach_probability:.3f}  "
                "move {:+.4f} {:+.4f} {:+.4f} m".format(*m.world)
            )
            alts = ", ".join(f"{s.node} {s.probability:.2f}" for s in ch.successors)
            lines.append(f"       expect {alts or '-'}")
        lines.append("choice at every node (gripper position unknown):")
        for n in net.nodes:
            ch = self.replan(n.id)
            if ch is None:
                what = "goal" if n.id == net.goal else "no path to the goal"
            else:
                kind = "final" if ch.macro.final else ",".join(ch.macro.classes)
                what = f"{' '.join(ch.macro.edges)}  {kind}, P(goal)={ch.reach_probability:.3f}"
            lines.append(f"  {n.id:<5} {what}")
        return "\n".join(lines) + "\n"


def reference_path(net: Network) -> tuple[str, ...]:
    """The edge ids the network's reference demonstration took, in its order (each edge's track is
    the reference's first occurrence of it, so an edge it took twice appears once); () without one."""
    ref = net.reference
    if ref is None:
        return ()
    mine = [e for e in net.edges if e.track is not None and e.track.demonstration == ref.demonstration]
    steps = [(e.track.t0, e.id) for e in mine if e.track is not None]
    return tuple(eid for _, eid in sorted(steps))


def blind(e: Edge) -> bool:
    """Whether a run takes edge ``e`` to have happened without sensing where it led: a deliberate
    transition (classed, neither ``S`` nor ``I``) whose every detection has no force signal at a
    run's signal-to-noise floor (:func:`dlovr.model.detection.no_force_signal`), so that its macro
    ends by its motion. ``S`` is sensed after it all the same; an ``I`` the motion does not choose is
    followed by the reference's motion and sensed at the spontaneous transition after it."""
    if not e.classes or {"S", "I"} & set(e.classes) or not e.detection:
        return False
    return all(no_force_signal(d.cls, d.params, MIN_SNR) for d in e.detection)


def _eliminate(v: str, rows: dict[str, dict[str, Fraction]], rhs: dict[str, dict[str, Fraction]]) -> None:
    """One Gauss-Jordan step on the sparse system ``rows`` (unknown -> coefficient) = ``rhs`` (node ->
    value): row ``v`` divided by its pivot, and ``v`` eliminated from every other row."""
    row, b = rows[v], rhs[v]
    piv = row.pop(v)
    for k in row:
        row[k] /= piv
    for k in b:
        b[k] /= piv
    for w, other in rows.items():
        c = other.pop(v, None) if w != v else None
        if not c:
            continue
        for k, a in row.items():
            other[k] = other.get(k, Fraction(0)) - c * a
        ob = rhs[w]
        for k, a in b.items():
            ob[k] = ob.get(k, Fraction(0)) - c * a


def load_runnable(path: str | Path) -> Program | NetworkProgram:
    """The program in the JSON file ``path``, read once: a :class:`NetworkProgram` when it says
    ``"kind": "network-program"``, else a compiled :class:`dlovr.model.program.Program`. Raises
    :class:`dlovr.model.program.ProgramError` (one line) for a bad file."""
    raw = read_json(path, ProgramError, "program file")
    if not isinstance(raw, dict) or raw.get("kind") != "network-program":
        return Program.from_json(raw, path)
    try:
        return NetworkProgram.from_json(raw)
    except NetworkError as e:
        raise ProgramError(where_msg(path, "", str(e))) from None
