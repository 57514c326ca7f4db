"""MIT Lincoln Laboratory's uncorrelated encounter model: its file, two Bayesian networks, sampling.

A model file (``em-model-manned-bayes``, ``model/uncor_*.txt``) holds an *initial* network over
G (geographic domain), A (airspace class), L (altitude layer, ft AGL), v (airspeed, kt), v-dot
(kt/s), h-dot (ft/min) and psi-dot (deg/s), and a *transition* network giving each dynamic
variable at t+1 from the static ones and the dynamic ones at t. Variable i's counts are an
``r_i x q_i`` matrix whose column is its parents' configuration (parents in index order, the
first varying fastest: MATLAB's column-major ``asub2ind``).

Sampling follows the reference's ``bn_sample.m`` and ``dbn_sample.m`` with its default Dirichlet
prior of 0 (plain counts; ``prior`` adds a constant to every count, as ``bn_dirichlet_prior.m``).
Two deliberate differences in the transition: (1) the parents' configuration is taken from the
current state at every step, as the reference's general branch (and its release 1.3.0) does;
its fast path, used for these models since 1.4.0, fixes it at the initial state, so every step
is drawn given the *initial* dynamic bins. (2) A configuration never seen in training (all
counts 0; 1 rotorcraft track of 120 s in 300 reaches one, 1 fixed-wing in 1500) keeps the
variable's bin, as the reference's ``setTransitionPriors.m`` prior on staying would; its
``select_random`` would take bin 1, the most negative rate. Values and tracks are
:mod:`~companion.campaign.traffic_track`'s.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from companion.errors import CompanionError

__all__ = [
    "TrafficModelError",
    "BayesNet",
    "EncounterModel",
    "read_model",
    "load_model",
    "sample_initial",
    "sample_dynamic",
    "MODEL_FILES",
    "MODELS_ENV",
]

MODELS_ENV = "COMPANION_ENCOUNTER_MODELS"
MODEL_FILES = {"rotorcraft": "uncor_1200only_rotorcraft_v1p2.txt", "fixedwing": "uncor_1200only_fwse_v1p2.txt"}
_SECTIONS = (
    "labels_initial",
    "G_initial",
    "r_initial",
    "N_initial",
    "labels_transition",
    "G_transition",
    "r_transition",
    "N_transition",
    "boundaries",
    "resample_rates",
)
_Lines = list[tuple[int, str]]  # (line number, stripped text) of one section


class TrafficModelError(CompanionError, ValueError):
    """An encounter model file is broken (the message names the file, the section and what is
    wrong), cannot be found, or cannot give what is asked of it."""


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity
class BayesNet:
    """A discrete Bayesian network with its counts.

    Attributes
    ----------
    labels : tuple of str, (n,)
    parents : tuple of tuple of int, (n,)
        Parents of each variable, in index order (the rows of ``G`` holding a 1 in its column).
    bins : (n,) int array
        Number of bins ``r_i`` of each variable.
    counts : tuple of arrays, (n,)
        ``counts[i]`` has shape ``(r_i, q_i)``, ``q_i`` the product of the parents' bins; a
        variable the network does not sample (the transition's time-t variables) has
        ``(r_i, 0)``.
    order : tuple of int, (n,)
        A topological order (parents first; ties by index).
    """

    labels: tuple[str, ...]
    parents: tuple[tuple[int, ...], ...]
    bins: np.ndarray
    counts: tuple[np.ndarray, ...]
    order: tuple[int, ...]

    @property
    def n(self) -> int:
        """Number of variables."""
        return len(self.labels)

    @functools.cached_property
    def _strides(self) -> tuple[np.ndarray, ...]:
        return tuple(
            np.cumprod([1, *self.bins[list(p)][:-1]]).astype(np.intp) if p else np.zeros(0, np.intp)
            for p in self.parents
        )

    def parent_index(self, i: int, values: ArrayLike) -> int | np.ndarray:
        """Column of ``counts[i]`` for the parents' configuration in ``values``.

        ``values`` is ``(n,)`` (gives an int) or ``(m, n)`` (gives ``(m,)``): 0-based bins of every
        variable. The column is ``sum_k values[p_k] * prod_{l<k} r[p_l]`` over the parents ``p_k``
        in index order (the reference's ``asub2ind``, 0-based); 0 for a root.
        """
        values = np.asarray(values)
        column = values[..., list(self.parents[i])] @ self._strides[i]
        return int(column) if values.ndim == 1 else column


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity
class EncounterModel:
    """An uncorrelated encounter model: its two networks, bin edges and resample rates.

    Attributes
    ----------
    name : str
        The file's stem.
    initial, transition : BayesNet
        The transition network's first ``initial.n`` variables are the initial ones (the
        dynamic ones at t), the others the dynamic ones at t+1.
    boundaries : tuple, (initial.n,)
        Bin edges ``(r_i + 1,)`` of each continuous variable, None for a discrete one (G, A).
    resample_rates : (initial.n,) float array
        Probability per second of drawing a variable's value anew inside its bin.
    temporal_map : tuple of (int, int)
        ``(index at t, index at t+1)`` in the transition network, one per dynamic variable.
    """

    name: str
    initial: BayesNet
    transition: BayesNet
    boundaries: tuple[np.ndarray | None, ...]
    resample_rates: np.ndarray
    temporal_map: tuple[tuple[int, int], ...]

    @property
    def dynamic(self) -> tuple[int, ...]:
        """Initial-network indices of the dynamic variables (v-dot, h-dot, psi-dot)."""
        return tuple(now for now, _ in self.temporal_map)

    @property
    def dynamic_next(self) -> tuple[int, ...]:
        """Transition-network indices of the dynamic variables at t+1, in :attr:`dynamic`'s order."""
        return tuple(nxt for _, nxt in self.temporal_map)

    def index(self, label: str) -> int:
        """Initial-network index of the variable labelled ``label`` (e.g. ``"L"``, ``"\\dot h"``)."""
        try:
            return self.initial.labels.index(label)
        except ValueError:
            raise TrafficModelError(f"model {self.name}: no variable {label!r} ({self.initial.labels})") from None


# ---------------------------------------------------------------------------- reading


def _fail(path: Path, section: str, what: str, line: int | None = None) -> TrafficModelError:
    where = f", line {line}" if line is not None else ""
    return TrafficModelError(f"{path}: section '{section}'{where}: {what}")


def _split_sections(path: Path, text: str) -> dict[str, _Lines]:
    """The non-blank lines of each ``# name`` section; unknown, repeated or missing ones fail."""
    sections: dict[str, _Lines] = {}
    current = None
    for line_no, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped.startswith("#"):
            current = stripped.lstrip("#").strip()
            if current not in _SECTIONS or current in sections:
                raise _fail(path, current, "unknown section" if current not in _SECTIONS else "appears twice", line_no)
            sections[current] = []
        elif stripped:
            if current is None:
                raise TrafficModelError(f"{path}: line {line_no}: text before the first section")
            sections[current].append((line_no, stripped))
    missing = [name for name in _SECTIONS if not sections.get(name)]
    if missing:
        raise TrafficModelError(
            f"{path}: missing or empty section(s) {', '.join(missing)} (truncated, or not an encounter model file?)"
        )
    return sections


def _numbers(path: Path, section: str, line_no: int, text: str) -> np.ndarray:
    tokens = text.split()
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        for k, token in enumerate(tokens):
            try:
                float(token)
            except ValueError:
                raise _fail(path, section, f"token {k + 1} {token!r} is not a number", line_no) from None
        raise
    if not np.all(np.isfinite(values)):
        k = int(np.flatnonzero(~np.isfinite(values))[0])
        raise _fail(path, section, f"token {k + 1} {tokens[k]!r} is not finite", line_no)
    return values


def _row(path: Path, section: str, lines: _Lines, size: int, what: str) -> tuple[int, np.ndarray]:
    """The numbers of a one-line section, which must be ``size`` of them."""
    if len(lines) != 1:
        raise _fail(path, section, f"has {len(lines)} lines, expected 1", lines[1][0])
    line_no, text = lines[0]
    values = _numbers(path, section, line_no, text)
    if values.size != size:
        raise _fail(path, section, f"{values.size} entries, expected {size} ({what})", line_no)
    values.flags.writeable = False
    return line_no, values


def _labels(path: Path, section: str, lines: _Lines) -> tuple[str, ...]:
    labels = tuple(label.strip().strip('"') for label in lines[0][1].split(","))
    if len(lines) != 1 or not all(labels):
        raise _fail(path, section, "must be one line of comma-separated, non-empty labels", lines[0][0])
    return labels


def _dag(path: Path, section: str, lines: _Lines, n: int) -> tuple[tuple[tuple[int, ...], ...], tuple[int, ...]]:
    """Parents and a topological order from the adjacency matrix (row parent, column child)."""
    if len(lines) != n:
        raise _fail(path, section, f"is not square: {len(lines)} rows for {n} variables (labels)")
    rows = []
    for line_no, text in lines:
        row = _numbers(path, section, line_no, text)
        if row.size != n:
            raise _fail(path, section, f"is not square: {row.size} entries in a row, expected {n}", line_no)
        if not np.all((row == 0) | (row == 1)):
            raise _fail(path, section, "entries must be 0 or 1", line_no)
        rows.append(row)
    g = np.array(rows, dtype=bool)
    parents = tuple(tuple(int(p) for p in np.flatnonzero(g[:, i])) for i in range(n))
    order: list[int] = []
    while len(order) < n:  # Kahn's algorithm, lowest index first (MATLAB toposort 'stable')
        ready = [i for i in range(n) if i not in order and all(p in order for p in parents[i])]
        if not ready:
            raise _fail(path, section, f"is not a DAG: a cycle among variables {sorted(set(range(n)) - set(order))}")
        order.append(ready[0])
    return parents, tuple(order)


def _counts(
    path: Path, section: str, lines: _Lines, bins: np.ndarray, parents: tuple[tuple[int, ...], ...], sampled: range
) -> tuple[np.ndarray, ...]:
    """Cut the flat counts into one column-major ``(r_i, q_i)`` matrix per sampled variable."""
    flat = np.concatenate([_numbers(path, section, line_no, text) for line_no, text in lines])
    shapes = [(int(bins[i]), int(np.prod(bins[list(parents[i])])) if i in sampled else 0) for i in range(bins.size)]
    expected = sum(r * q for r, q in shapes)
    if flat.size != expected:
        raise _fail(
            path,
            section,
            f"{flat.size} numbers, expected {expected} (sum of r_i * q_i over "
            f"variables {sampled.start + 1}..{sampled.stop})",
        )
    if np.any(flat < 0):
        raise _fail(path, section, "negative counts")
    ends = np.cumsum([r * q for r, q in shapes])
    counts = tuple(flat[end - r * q : end].reshape((r, q), order="F") for (r, q), end in zip(shapes, ends))
    for c in counts:
        c.flags.writeable = False
    return counts


def _network(path: Path, sections: dict[str, _Lines], suffix: str, sampled_from: int) -> BayesNet:
    labels = _labels(path, f"labels_{suffix}", sections[f"labels_{suffix}"])
    parents, order = _dag(path, f"G_{suffix}", sections[f"G_{suffix}"], len(labels))
    line_no, r = _row(path, f"r_{suffix}", sections[f"r_{suffix}"], len(labels), f"labels_{suffix}'s count")
    if np.any(r < 1) or np.any(r != np.round(r)):
        raise _fail(path, f"r_{suffix}", "bin counts must be integers >= 1", line_no)
    bins = r.astype(np.intp)
    bins.flags.writeable = False
    counts = _counts(path, f"N_{suffix}", sections[f"N_{suffix}"], bins, parents, range(sampled_from, len(labels)))
    return BayesNet(labels, parents, bins, counts, order)


def _boundaries(path: Path, lines: _Lines, initial: BayesNet) -> tuple[np.ndarray | None, ...]:
    if len(lines) != initial.n:
        raise _fail(path, "boundaries", f"{len(lines)} lines, expected {initial.n} (one per variable)")
    edges: list[np.ndarray | None] = []
    for i, (line_no, text) in enumerate(lines[: initial.n]):
        e = None if text == "*" else _numbers(path, "boundaries", line_no, text)
        if e is not None and (e.size != initial.bins[i] + 1 or np.any(np.diff(e) < 0)):
            raise _fail(
                path,
                "boundaries",
                f"variable {initial.labels[i]!r}: {e.size} edges, expected "
                f"{initial.bins[i] + 1} non-decreasing (its bins + 1) or '*'",
                line_no,
            )
        if e is not None:
            e.flags.writeable = False
        edges.append(e)
    return tuple(edges)


def _temporal_map(path: Path, initial: BayesNet, transition: BayesNet) -> tuple[tuple[int, int], ...]:
    """Pair each transition label ``X(t)`` with ``X(t+1)``; check both networks agree."""
    n0 = initial.n
    now = tuple(label.removesuffix("(t)") for label in transition.labels[:n0])
    if now != initial.labels or not np.array_equal(transition.bins[:n0], initial.bins):
        raise _fail(
            path,
            "labels_transition",
            f"the first {n0} variables must be the initial ones with the same bins, got {transition.labels[:n0]}",
        )
    pairs = []
    for i, label in enumerate(transition.labels[:n0]):
        if label.endswith("(t)"):
            nxt = label[:-3] + "(t+1)"
            if nxt not in transition.labels or transition.bins[transition.labels.index(nxt)] != initial.bins[i]:
                raise _fail(path, "labels_transition", f"{label!r} has no {nxt!r} with its bins")
            pairs.append((i, transition.labels.index(nxt)))
    if sorted(nxt for _, nxt in pairs) != list(range(n0, transition.n)):
        raise _fail(
            path, "labels_transition", f"variables {n0 + 1}..{transition.n} must be the '(t+1)' twins of the '(t)' ones"
        )
    return tuple(pairs)


def read_model(path: str | os.PathLike) -> EncounterModel:
    """Read an encounter model file (the format of the reference's ``em_read.m``).

    Raises
    ------
    TrafficModelError
        Naming the file, the section and what is wrong: a missing, unknown or empty section,
        a non-numeric token (with its line), ``G`` not square or not a DAG, ``r`` of the wrong
        length, the wrong count of numbers in ``N``, bad bin edges or resample rates.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise TrafficModelError(f"{path}: cannot read the encounter model: {exc}") from exc
    sections = _split_sections(path, text)
    initial = _network(path, sections, "initial", 0)
    transition = _network(path, sections, "transition", initial.n)
    pairs = _temporal_map(path, initial, transition)
    boundaries = _boundaries(path, sections["boundaries"], initial)
    line_no, rates = _row(path, "resample_rates", sections["resample_rates"], initial.n, "one per initial variable")
    if np.any((rates < 0) | (rates > 1)):
        raise _fail(path, "resample_rates", "rates must be in [0, 1]", line_no)
    return EncounterModel(path.stem, initial, transition, boundaries, rates, pairs)


#: The models shipped with the package (MIT LL's files, unchanged, with their BSD licence).
PACKAGED_MODELS = Path(__file__).resolve().parents[1] / "data" / "encounter_models"


def models_directory(directory: str | os.PathLike | None = None) -> Path:
    """``directory``, else ``$COMPANION_ENCOUNTER_MODELS``, else the packaged copy
    (``companion/data/encounter_models``)."""
    if directory is None:
        directory = os.environ.get(MODELS_ENV) or PACKAGED_MODELS
    return Path(directory).resolve()


@functools.lru_cache(maxsize=8)
def _read_cached(path: Path) -> EncounterModel:
    return read_model(path)


def load_model(kind: str, directory: str | os.PathLike | None = None) -> EncounterModel:
    """The ``"rotorcraft"`` or ``"fixedwing"`` model from :func:`models_directory`, read once per path."""
    if kind not in MODEL_FILES:
        raise TrafficModelError(f"unknown encounter model kind {kind!r} (known: {', '.join(MODEL_FILES)})")
    path = models_directory(directory) / MODEL_FILES[kind]
    if not path.is_file():
        raise TrafficModelError(
            f"encounter model file {path} not found (pass directory= or set "
            f"{MODELS_ENV} to the folder holding {MODEL_FILES[kind]})"
        )
    return _read_cached(path)


# ---------------------------------------------------------------------------- sampling


def _draw(counts: np.ndarray, columns: np.ndarray, prior: float, u: np.ndarray) -> np.ndarray:
    """Bins drawn from the (counts + prior) columns, one per uniform ``u`` in [0, 1)."""
    cumulative = np.cumsum(counts[:, columns] + prior, axis=0)  # (r, m)
    total = cumulative[-1]
    if np.any(total <= 0):
        raise TrafficModelError(
            f"a parents' configuration without counts (column {int(columns[np.argmax(total <= 0)])}); use prior > 0"
        )
    return np.sum(cumulative <= _threshold(u, total), axis=0)


def _threshold(u: np.ndarray | float, total: np.ndarray | float) -> np.ndarray:
    """``u * total`` kept below ``total`` (rounding could reach it): the drawn bin has weight."""
    return np.minimum(u * total, np.nextafter(total, 0.0))


def sample_initial(
    model: EncounterModel, rng: np.random.Generator, *, size: int | None = None, prior: float = 0.0
) -> np.ndarray:
    """Sample the initial network in topological order (the reference's ``bn_sample``).

    Returns the ``(n,)`` 0-based bins of the initial variables (G, A, L, v, v-dot, h-dot,
    psi-dot), or ``(size, n)`` for ``size`` independent samples (vectorised). ``prior`` is the
    Dirichlet prior added to every count (the reference's default: 0).
    """
    net = model.initial
    m = 1 if size is None else int(size)
    bins = np.zeros((m, net.n), dtype=np.intp)
    for i in net.order:
        bins[:, i] = _draw(net.counts[i], net.parent_index(i, bins), prior, rng.random(m))
    return bins[0] if size is None else bins


def sample_dynamic(
    model: EncounterModel, initial_bins: ArrayLike, duration_s: float, rng: np.random.Generator, *, prior: float = 0.0
) -> np.ndarray:
    """Step the transition network once a second from an initial sample.

    Parameters
    ----------
    initial_bins : (n,) int array_like
        An initial sample (:func:`sample_initial`).
    duration_s : float
        Whole seconds ``T`` (the reference's ``sample_time``).
    prior : float
        Dirichlet prior added to every transition count.

    Returns
    -------
    (T, d) int array
        0-based bins of the dynamic variables (:attr:`EncounterModel.dynamic`: v-dot, h-dot,
        psi-dot) at t = 0, 1, ..., T-1 s; row 0 is the initial sample's.
    """
    steps = int(round(duration_s))
    if steps < 1 or abs(steps - duration_s) > 1e-9:
        raise TrafficModelError(f"duration_s must be a whole number of seconds >= 1, got {duration_s}")
    net = model.transition
    now, nxt = np.array(model.dynamic), np.array(model.dynamic_next)
    sampled = [i for i in net.order if i in model.dynamic_next]
    held = dict((n1, n0) for n0, n1 in model.temporal_map)
    state = np.zeros(net.n, dtype=np.intp)
    state[: model.initial.n] = np.asarray(initial_bins, dtype=np.intp)
    out = np.empty((steps, now.size), dtype=np.intp)
    out[0] = state[now]
    u = rng.random((steps, len(sampled)))
    for t in range(1, steps):
        for k, i in enumerate(sampled):
            state[i] = _step(net.counts[i][:, net.parent_index(i, state)], prior, u[t, k], state[held[i]])
        state[now] = state[nxt]
        out[t] = state[now]
    return out


def _step(column: np.ndarray, prior: float, u: float, held: int) -> int:
    """One transition draw; a parents' configuration never seen in training keeps its bin."""
    weights = column + prior
    total = weights.sum()
    if total <= 0:
        return held
    return int(np.searchsorted(np.cumsum(weights), _threshold(u, total), side="right"))
