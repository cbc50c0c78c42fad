"""Every particle's configs against every point of it, evaluated once per distinct value pair.

After resampling most particles hold identical copies of a contact, and a prediction step
moves a copy or not, so across 100 particles a contact (its point, config and orientation) takes
only a few distinct values: its *states*. The penetration of a (config, point) pair depends only
on the two states, so it is evaluated once per state pair that some particle holds and credited
to every particle holding both. Candidate pairs come from k-d tree range searches (configs
turned about the vertical: within the deep region's farthest reach from E's z axis, in the
plane; others: within the ball around the deep region), then the particle-set test, then each
pair's per-layer reach and the grid cell's smallest corner value
(:mod:`stucco_drake.core.deep_region`); only then are rotated configs rotated, with the fixed
rounding of :mod:`stucco_drake.core.float32_frames`, and the grid interpolated.

The sums are formed exactly as a per-particle, per-orientation pass over all pairs forms them
(the tracker's float64 sums of float32 excesses are compared against 0 and against each other,
so the order of additions is part of the result): for each particle, the orientations in slot
order, and within one the pairs in (config, point) order, each orientation's subtotal added to
the running total."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from stucco_drake.core.deep_region import axial_slack2, could_penetrate, within_layer_reach
from stucco_drake.core.float32_frames import in_frame_float32

#: Above this many states per column and particle, particles share too little for the state
#: pairs to beat a pass over each particle.
_MAX_STATES_PER_PARTICLE = 0.125
#: Horizontal-to-vertical trade of the ellipsoid that holds the axial screen's cylinder.
_ELLIPSOID_SHAPE = 1.0


@dataclass(frozen=True)
class ColumnStates:
    """Distinct values of each column of a (n_particles, n) table of entries.

    Attributes:
        ids: (n_particles, n) global state number of each entry; a column's states are
            numbered consecutively from ``offsets[column]``.
        offsets: (n,) first state number of each column.
        counts: (n,) number of states of each column.
        holders: (n_states,) a particle holding each state.
        columns: (n_states,) the column of each state.
        masks: (ceil(n_particles / 32), n_states) uint32 bit sets of the particles holding
            each state (particle k is bit k % 32 of word k // 32), word-major: one gather per
            word is several times faster than gathering rows.
    """

    ids: np.ndarray
    offsets: np.ndarray
    counts: np.ndarray
    holders: np.ndarray
    columns: np.ndarray
    masks: np.ndarray


#: Odd 64-bit multipliers that spread each key's bits over the hash.
_MIXERS = (0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9, 0xD6E8FEB86659FD93,
           0xFF51AFD7ED558CCD, 0xC4CEB9FE1A85EC53, 0x94D049BB133111EB, 0xBF58476D1CE4E5B9)


def _sorted_by_value(by_column: list[np.ndarray]) -> np.ndarray:
    """(n, n_particles) particle order of each column with equal entries adjacent.

    Sorts a hash of the keys whose low bits carry the particle number: one sort of plain
    integers instead of a sort on every key. Equal entries have equal hashes, so they end up
    adjacent; a collision (two values, one hash) only interleaves their entries.
    """
    n_particles = by_column[0].shape[1]
    index_bits = max(1, int(n_particles - 1).bit_length())
    digest = np.zeros(by_column[0].shape, dtype=np.uint64)
    for k, mixer in zip(by_column, _MIXERS, strict=False):
        digest ^= k.astype(np.uint64) * np.uint64(mixer)
    digest = (digest >> np.uint64(index_bits)) << np.uint64(index_bits)
    digest |= np.arange(n_particles, dtype=np.uint64)[None, :]
    return (np.sort(digest, axis=1) & np.uint64((1 << index_bits) - 1)).astype(np.intp)


def column_states(keys: list[np.ndarray]) -> ColumnStates:
    """Group equal entries of each column: ``keys`` (at most eight) are (n_particles, n) integer
    arrays (e.g. the bits of x, y, z), entries being equal when all keys are.

    Columns that every particle holds alike (after resampling, most of them) are one state
    each, found by comparing with the first particle; only the others are sorted. There a
    state is a run of equal entries in the hash order, so every state holds one value
    exactly; a hash collision can only split a value into two states (the same sums, a few
    more evaluations), never merge two values.
    """
    n_particles, n = keys[0].shape
    uniform = np.ones(n, dtype=bool)
    for k in keys:
        uniform &= (k == k[:1]).all(axis=0)
    diverse = np.flatnonzero(~uniform)
    by_column = [np.ascontiguousarray(k[:, diverse].T) for k in keys]  # (m, n_particles)
    order = _sorted_by_value(by_column)
    flat_order = order + (np.arange(diverse.size) * n_particles)[:, None]  # into the ravel
    new_state = np.zeros((diverse.size, n_particles), dtype=bool)
    new_state[:, 0] = True
    for k in by_column:
        ranked = k.ravel()[flat_order]
        new_state[:, 1:] |= ranked[:, 1:] != ranked[:, :-1]
    counts = np.ones(n, dtype=np.int64)
    counts[diverse] = new_state.sum(axis=1)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    n_states = int(counts.sum())
    # A diverse column's states in rank order, numbered from its offset.
    local = np.empty((diverse.size, n_particles), dtype=np.int64)
    local.ravel()[flat_order] = np.cumsum(new_state, axis=1) - 1
    diverse_ids = local + offsets[diverse][:, None]
    ids = np.repeat(offsets[None, :], n_particles, axis=0)
    ids[:, diverse] = diverse_ids.T
    holders = np.zeros(n_states, dtype=np.intp)
    holders[_ranges(offsets[diverse], counts[diverse])] = order[new_state]
    masks = _particle_masks(diverse_ids, n_states)
    masks[:, offsets[uniform]] = _all_particles(n_particles)[:, None]
    return ColumnStates(ids, offsets, counts, holders, np.repeat(np.arange(n), counts), masks)


def _ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Concatenated ranges [start, start + length) as one index array."""
    within = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    return np.repeat(starts, lengths) + within


def _all_particles(n_particles: int) -> np.ndarray:
    """The mask words (uint32) with every particle's bit set."""
    held = [min(32, n_particles - 32 * word) for word in range((n_particles + 31) // 32)]
    return np.array([(1 << bits) - 1 for bits in held], dtype=np.uint32)


def _particle_masks(ids: np.ndarray, n_states: int) -> np.ndarray:
    """(n_words, n_states) bit sets of the particles holding each state, from the (n,
    n_particles) state numbers. Each word is a bincount of distinct powers of two below 2^32,
    exact in float64, so no bitwise scatter is needed."""
    n, n_particles = ids.shape
    n_words = (n_particles + 31) // 32
    masks = np.empty((n_words, n_states), dtype=np.uint32)
    bits = np.ldexp(1.0, np.arange(n_particles) % 32)
    for word in range(n_words):
        lo, hi = 32 * word, min(32 * word + 32, n_particles)
        weights = np.broadcast_to(bits[lo:hi], (n, hi - lo)).ravel()
        masks[word] = np.bincount(ids[:, lo:hi].ravel(), weights, minlength=n_states)
    return masks


def float_bits(array: np.ndarray) -> np.ndarray:
    """The bit pattern of a float32 array as uint32 (equal values, equal bits; -0.0 != 0.0)."""
    return np.ascontiguousarray(array, dtype=np.float32).view(np.uint32)


def _state_table(points, configs, rotation_index):
    """States of the contacts, with their values. A contact's point, config and orientation
    change together (pxdyn moves both, ReplaceBad copies all three), so one grouping of the
    three serves as both the point states and the config states."""
    states = column_states([float_bits(a) for a in (*points, *configs)]
                           + [rotation_index.astype(np.uint32)])  # fmt: skip
    point_world = points[:, states.holders, states.columns]
    config_world = configs[:, states.holders, states.columns]
    slot = rotation_index[states.holders, states.columns].astype(np.int64)
    return states, point_world, config_world, slot


def _in_slot_frames(vectors, slot, frames_t, identity):
    """(3, k) float32 coordinates of world ``vectors`` along the axes of each one's slot; an
    exactly-identity slot leaves them as they are (as the per-orientation pass does)."""
    if identity[slot].all():
        return vectors
    rotated = in_frame_float32(frames_t[slot], vectors)
    return np.where(identity[slot][None, :], vectors, rotated)


def _distinct(keys: np.ndarray, n_keys: int):
    """(distinct keys ascending, index of each key among them) for keys in [0, n_keys)."""
    present = np.zeros(n_keys, dtype=bool)
    present[keys] = True
    distinct = np.flatnonzero(present)
    position = np.zeros(n_keys, dtype=np.int64)
    position[distinct] = np.arange(distinct.size)
    return distinct, position[keys]


def _penetrating_state_pairs(grid, tolerance, region, config_state, point_state, offset, table,
                             frames):  # fmt: skip
    """The state pairs (and their float32 excess) that penetrate deeper than ``tolerance``.

    ``offset`` (3, k) float32 is each pair's point minus config (world): for a config in an
    exactly-identity orientation that is the difference the per-orientation pass forms.
    """
    slot = table[3]
    identity = frames[1]
    inverse_h = np.float32(1.0 / grid.resolution)
    origin_cells = (grid.lower / grid.resolution).astype(np.float32)
    pair_slot = slot[config_state]
    which = np.flatnonzero(identity[pair_slot])
    cells = [offset[a, which] * inverse_h - origin_cells[a] for a in range(3)]
    rotated = np.flatnonzero(~identity[pair_slot])
    if rotated.size:
        exact = _rotated_differences(config_state[rotated], point_state[rotated], table, frames)
        which = np.concatenate([which, rotated])
        cells = [np.concatenate([c, e * inverse_h - o])
                 for c, e, o in zip(cells, exact, origin_cells, strict=True)]  # fmt: skip
    keep = np.flatnonzero(could_penetrate(grid, region, cells))
    excess = np.maximum(-grid.at_cell_coordinates(*(c[keep] for c in cells)) - tolerance, 0.0)
    hit = which[keep[excess > 0.0]]
    return config_state[hit], point_state[hit], excess[excess > 0.0]


def _rotated_differences(config_state, point_state, table, frames):
    """Point minus config along the config's slot axes, (3, k) float32, as the per-orientation
    pass forms it: both rotated (each (point state, slot) and config state once), then
    subtracted."""
    _, point_world, config_world, slot = table
    frames_t, identity = frames
    n_slots = len(frames_t)
    pair_slot = slot[config_state]
    point_key, point_of_pair = _distinct(point_state * n_slots + pair_slot,
                                         point_world.shape[1] * n_slots)  # fmt: skip
    points_e = _in_slot_frames(point_world[:, point_key // n_slots], point_key % n_slots,
                               frames_t, identity)  # fmt: skip
    config_key, config_of_pair = _distinct(config_state, config_world.shape[1])
    configs_e = _in_slot_frames(np.take(config_world, config_key, axis=1), slot[config_key],
                                frames_t, identity)  # fmt: skip
    return np.take(points_e, point_of_pair, axis=1) - np.take(configs_e, config_of_pair, axis=1)


def penetrating_entries(grid, tolerance, region, points, configs, rotation_index, rotations,
                        budget):  # fmt: skip
    """The (config, point) state pairs that penetrate beyond ``tolerance`` and who holds them.

    Args:
        grid: the robot's signed distance in frame E (m).
        tolerance: penetration (m) ignored per pair.
        region: :func:`deep_region` of the grid at this tolerance.
        points, configs: (3, n_particles, n) float32 world positions (m).
        rotation_index: (n_particles, n) orientation slot of each config.
        rotations: (n_slots, 3, 3) R_WE of each slot.
        budget: state pairs per vectorised block; bounds scratch memory.

    Returns:
        :class:`PenetratingPairs`, or None when the particles share too few states for this to
        pay off.
    """
    n_particles = points.shape[1]
    if region is None:
        return _no_pairs(n_particles)
    n_particles = points.shape[1]
    table = _state_table(points, configs, rotation_index)
    states, point_world, config_world, slot = table
    if states.counts.mean() > _MAX_STATES_PER_PARTICLE * n_particles:
        return None  # particles too diverse: a pass over each particle's pairs is cheaper
    rotations = np.asarray(rotations, dtype=np.float64)
    frames = (np.transpose(rotations, (0, 2, 1)).astype(np.float32),
              (rotations == np.eye(3)).all(axis=(1, 2)))  # fmt: skip
    axial, slack2 = axial_slack2(rotations, region, grid.resolution)
    config_near, point_near = near_state_pairs(grid, region, table, rotations, axial, slack2)
    center_shift = (rotations @ region.center)[slot].T.astype(np.float32)
    hits = []
    for k in range(0, config_near.size, max(1, int(budget))):
        config_state, point_state = config_near[k : k + budget], point_near[k : k + budget]
        held = np.flatnonzero(np.bitwise_or.reduce(
            _shared_words(config_state, point_state, states)))  # fmt: skip
        config_state, point_state = config_state[held], point_state[held]
        # np.take: gathering columns of a (3, n) array by fancy indexing is ~10x slower.
        offset = np.take(point_world, point_state, axis=1) - np.take(config_world, config_state,
                                                                     axis=1)  # fmt: skip
        near = np.flatnonzero(_could_reach(grid, region, offset, slot[config_state], axial,
                                           slack2, np.take(center_shift, config_state, axis=1)))
        hits.append(_penetrating_state_pairs(grid, tolerance, region, config_state[near],
                                             point_state[near], np.take(offset, near, axis=1),
                                             table, frames))  # fmt: skip
    if not hits:
        return _no_pairs(n_particles)
    config_state, point_state, excess = (np.concatenate(v) for v in zip(*hits, strict=True))
    return PenetratingPairs(slot[config_state], states.columns[config_state],
                            states.columns[point_state], excess,
                            _holders_of_both(config_state, point_state, states, n_particles))


@dataclass(frozen=True)
class PenetratingPairs:
    """State pairs that penetrate, k of them: the config's orientation ``slot``, the contact
    columns of the ``config`` and the ``point``, the float32 ``excess`` (m) beyond the
    tolerance, and ``holders`` (k, n_particles) bool, the particles holding both states."""

    slot: np.ndarray
    config: np.ndarray
    point: np.ndarray
    excess: np.ndarray
    holders: np.ndarray


def _no_pairs(n_particles: int) -> PenetratingPairs:
    empty = np.zeros(0, dtype=np.int64)
    return PenetratingPairs(empty, empty, empty, np.zeros(0, dtype=np.float32),
                            np.zeros((0, n_particles), dtype=bool))  # fmt: skip


def near_state_pairs(grid, region, table, rotations, axial, slack2):
    """Every (config state, point state) whose world positions could put the point in the
    robot's deep region, held by a particle or not: a superset of the penetrating pairs.

    Configs of slots turned about the vertical (``axial``) look within the farthest layer
    reach (plus ``slack2``) of E's z axis, the others in the ball around the deep region: range
    searches of k-d trees of the states, so only nearby pairs are ever formed.
    """
    _, point_world, config_world, slot = table
    points = point_world.T.astype(np.float64)
    configs = config_world.T.astype(np.float64)
    state_axial = axial[slot]
    found = []
    turned = np.flatnonzero(state_axial)
    if turned.size:
        # Contacts spread mostly horizontally: a vertical bound would prune little, so
        # the search is in the plane (the pair's layer is tested afterwards).
        radius = float(np.sqrt(region.layer_reach2.max() + slack2[axial].max())) + 1e-6
        found.append((turned, cKDTree(configs[turned, :2]).sparse_distance_matrix(
            cKDTree(points[:, :2]), radius, output_type="ndarray")))  # fmt: skip
    other = np.flatnonzero(~state_axial)
    if other.size:
        centers = configs[other] + (rotations @ region.center)[slot[other]]
        found.append((other, cKDTree(centers).sparse_distance_matrix(
            cKDTree(points), region.radius * (1 + 1e-9), output_type="ndarray")))  # fmt: skip
    if not found:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    return (np.concatenate([which[pairs["i"]] for which, pairs in found]),
            np.concatenate([pairs["j"].astype(np.int64) for _, pairs in found]))


def _could_reach(grid, region, offset, pair_slot, axial, slack2, center_shift):
    """Which pairs (world offsets (3, k) float32, point minus config) lie near enough to the
    robot's deep region to penetrate: configs turned about the vertical by the layer reach,
    the others by the ball around the region (its center ``center_shift`` (3, k) from each
    config, world). Both are exact screens; float32 rounding of the ball's test (~1e-7 m) is
    far inside its one-cell slack."""
    if axial[pair_slot].all():
        return within_layer_reach(grid, region, offset, slack2[pair_slot])
    distance2 = np.zeros(offset.shape[1], dtype=np.float32)
    for axis in range(3):
        distance2 += (offset[axis] - center_shift[axis]) ** 2
    ball = distance2 <= np.float32(region.radius * region.radius)
    return ball & (~axial[pair_slot]
                   | within_layer_reach(grid, region, offset, slack2[pair_slot]))  # fmt: skip


def _shared_words(config_state, point_state, states) -> list[np.ndarray]:
    """Per mask word, the (k,) bits of the particles holding both states of each pair."""
    return [words.take(config_state) & words.take(point_state) for words in states.masks]


def _holders_of_both(config_state, point_state, states, n_particles: int) -> np.ndarray:
    """(k, n_particles) bool: the particles holding both states of each pair, the bits of the
    intersection of their particle sets."""
    both = np.stack(_shared_words(config_state, point_state, states), axis=1).astype("<u4")
    bits = np.unpackbits(both.view(np.uint8), axis=1, bitorder="little")[:, :n_particles]
    return bits.view(bool)


def ordered_sums(pairs: PenetratingPairs, n_particles: int, n_points: int):
    """per_particle (n_particles,) and per_point (n_particles, n_points) float64 sums of the
    pairs' excess over their holders, added in the order of a per-particle, per-orientation
    pass (module doc).

    A particle holds one state per contact, so it holds at most one pair per (config, point):
    with the pairs sorted by (slot, config, point), the particle-major nonzeros of the holders
    are each particle's entries in summation order, with no sort of the entries themselves.
    """
    per_particle = np.zeros(n_particles)
    per_point = np.zeros((n_particles, n_points))
    if pairs.excess.size == 0:
        return per_particle, per_point
    slot, config, point = pairs.slot, pairs.config, pairs.point
    weights = pairs.excess.astype(np.float64)

    def folded(order, outer_of):
        """Sum each particle's entries in ``order`` of the pairs, each (outer, slot) group's
        subtotal added to its ``outer`` group's running total (bincount adds in input order,
        one addition per entry); the groups are consecutive in that order."""
        # Flat nonzeros of the particle-major copy: several times faster than 2-D nonzero.
        particle, rank = np.divmod(np.flatnonzero(pairs.holders[order].T.copy()), order.size)
        pair = order[rank]
        outer = outer_of(particle, pair)
        group_slot = slot[pair]
        first = np.ones(pair.size, dtype=bool)
        first[1:] = (outer[1:] != outer[:-1]) | (group_slot[1:] != group_slot[:-1])
        subtotal = np.bincount(np.cumsum(first) - 1, weights[pair])
        return outer[first], subtotal

    rows, subtotal = folded(np.lexsort((point, config, slot)), lambda particle, _: particle)
    per_particle += np.bincount(rows, subtotal, minlength=n_particles)
    rows, subtotal = folded(np.lexsort((config, slot, point)),
                            lambda particle, pair: particle * n_points + point[pair])
    per_point += np.bincount(rows, subtotal, minlength=n_particles * n_points).reshape(
        n_particles, n_points
    )
    return per_particle, per_point
