"""Skeleton facts (salad_core.skeleton) against the official HumanML3D / SALAD tables and real data."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.skeleton import MID_NAMES, PART_MIRROR, PART_NAMES, available_skeletons, get_skeleton

HML = get_skeleton("humanml3d")
KIT = get_skeleton("kit")
BOTH = [HML, KIT]

# Official SALAD utils/paramUtil.py neighbour lists (salad_official_facts.md §1.4).
T2M_ADJ_LIST = {
    0: [1, 2, 3], 1: [0, 4], 2: [0, 5], 3: [0, 6], 4: [1, 7], 5: [2, 8], 6: [3, 9], 7: [4, 10],
    8: [5, 11], 9: [6, 12, 13, 14], 10: [7], 11: [8], 12: [9, 15], 13: [9, 16], 14: [9, 17],
    15: [12], 16: [13, 18], 17: [14, 19], 18: [16, 20], 19: [17, 21], 20: [18], 21: [19],
}
KIT_ADJ_LIST = {
    0: [1, 11, 16], 1: [0, 2], 2: [1, 3], 3: [2, 4, 5, 8], 4: [3], 5: [3, 6], 6: [5, 7], 7: [6],
    8: [3, 9], 9: [8, 10], 10: [9], 11: [0, 12], 12: [11, 13], 13: [12, 14], 14: [13, 15], 15: [14],
    16: [0, 17], 17: [16, 18], 18: [17, 19], 19: [18, 20], 20: [19],
}


HML_MID_ROOT, HML_MID_CHEST = MID_NAMES.index("root"), MID_NAMES.index("chest")


def _side(sk, j):
    """'L', 'R' or '' from the joint's name (KIT: MMM-style prefixes in Guo's convention)."""
    name = sk.joint_names[j]
    if sk.name == "humanml3d":
        return "L" if name.startswith("left_") else "R" if name.startswith("right_") else ""
    return name[0] if len(name) >= 2 and name[0] in "LR" and name[1] in "SEWHKAMF" else ""


def _part_joints(sk, part):
    """Joints that feed a latent part through both pooling levels (J -> 12 -> 7)."""
    mids = sk.pooling_levels[1][part]
    return set().union(*(sk.pooling_levels[0][m] for m in mids))


@pytest.mark.parametrize("sk", BOTH, ids=lambda s: s.name)
def test_parents_and_chains_are_consistent(sk):
    assert sk.parents[0] == -1
    assert all(0 <= p < j for j, p in enumerate(sk.parents) if j > 0)
    seen = []
    for chain in sk.kinematic_chains:
        for a, b in zip(chain[:-1], chain[1:]):
            assert sk.parents[b] == a, (chain, a, b)
        seen.extend(chain[1:])
    assert sorted(seen) == list(range(1, sk.num_joints))   # every non-root joint exactly once
    assert len(sk.joint_names) == len(sk.raw_offsets) == sk.num_joints
    np.testing.assert_allclose(np.linalg.norm(np.asarray(sk.raw_offsets[1:], float), axis=-1), 1.0)


@pytest.mark.parametrize("sk", BOTH, ids=lambda s: s.name)
def test_adjacency_is_a_symmetric_tree(sk):
    adj = sk.adjacency
    assert adj.shape == (sk.num_joints, sk.num_joints)
    assert (adj == adj.T).all() and not adj.diagonal().any()
    assert adj.sum() == 2 * (sk.num_joints - 1)
    # connected: the reachability from the root covers every joint
    reach = np.eye(sk.num_joints, dtype=bool)[0]
    for _ in range(sk.num_joints):
        reach = reach | (adj[reach].any(0))
    assert reach.all()


@pytest.mark.parametrize("sk,official", [(HML, T2M_ADJ_LIST), (KIT, KIT_ADJ_LIST)], ids=["humanml3d", "kit"])
def test_neighbour_lists_equal_official_adj_list(sk, official):
    assert {j: list(n) for j, n in enumerate(sk.neighbors)} == official
    assert HML.neighbors[9] == (6, 12, 13, 14)


def test_humanml3d_special_joints():
    assert HML.num_joints == 22 and HML.feature_dim == 263
    assert HML.contact_joints == (7, 10, 8, 11)
    assert HML.face_joint_indx == (2, 1, 17, 16)
    r_hip, l_hip, sdr_r, sdr_l = HML.face_joint_indx
    assert [_side(HML, j) for j in (r_hip, l_hip, sdr_r, sdr_l)] == ["R", "L", "R", "L"]
    assert [_side(HML, j) for j in HML.fid_l] == ["L", "L"] and [_side(HML, j) for j in HML.fid_r] == ["R", "R"]
    assert HML.leg_bones == (5, 8)
    assert get_skeleton("t2m") is HML and get_skeleton(HML) is HML


def test_kit_feature_dim_and_slices():
    assert KIT.num_joints == 21 and KIT.feature_dim == 251
    s = KIT.feature_slices
    assert [s[k].start for k in ("ric", "rot", "local_vel", "contacts")] == [4, 64, 184, 247]
    assert s["contacts"].stop == 251
    assert KIT.contact_joints == (19, 20, 14, 15)


@pytest.mark.parametrize("sk", BOTH, ids=lambda s: s.name)
def test_feature_slices_tile_the_vector(sk):
    s = sk.feature_slices
    order = ["root_rot_vel", "root_lin_vel", "root_y", "ric", "rot", "local_vel", "contacts"]
    assert s[order[0]].start == 0 and s[order[-1]].stop == sk.feature_dim
    for a, b in zip(order[:-1], order[1:]):
        assert s[a].stop == s[b].start
    j = sk.num_joints
    assert s["ric"].stop - s["ric"].start == 3 * (j - 1) and s["rot"].stop - s["rot"].start == 6 * (j - 1)


@pytest.mark.parametrize("sk", BOTH, ids=lambda s: s.name)
def test_joint_feature_index_covers_every_column_once(sk):
    cols = [c for idx in sk.joint_feature_index for c in idx]
    assert sorted(cols) == list(range(sk.feature_dim))
    assert len(sk.joint_feature_index[0]) == 7
    sizes = {len(idx) for j, idx in enumerate(sk.joint_feature_index) if j > 0}
    assert sizes == {12, 13}
    c0 = sk.feature_slices["contacts"].start
    for k, j in enumerate(sk.contact_joints):
        assert sk.joint_feature_index[j][-1] == c0 + k


@pytest.mark.parametrize("sk", BOTH, ids=lambda s: s.name)
def test_mirror_map_is_an_involution_pairing_left_and_right(sk):
    m = np.asarray(sk.mirror_map)
    np.testing.assert_array_equal(m[m], np.arange(sk.num_joints))
    assert m[0] == 0
    for j in range(sk.num_joints):
        side = _side(sk, j)
        if side == "":
            assert m[j] == j, sk.joint_names[j]
        else:
            assert _side(sk, m[j]) == {"L": "R", "R": "L"}[side], (sk.joint_names[j], sk.joint_names[m[j]])
    # rest directions are mirror images: raw[m(j)] = diag(-1, 1, 1) raw[j] (needed by mirror_features)
    raw = np.asarray(sk.raw_offsets, float)
    np.testing.assert_array_equal(raw[m], raw * [-1, 1, 1])
    if sk.bone_lengths is None:
        return
    for a, b in sk.mirror_pairs:
        assert sk.joint_names[a].replace("left", "") == sk.joint_names[b].replace("right", "")


def test_humanml3d_part_groups_contain_the_right_joints():
    names = PART_NAMES
    part_of = {name: {j for j, p in enumerate(HML.joint_to_part) if p == i} for i, name in enumerate(names)}
    assert part_of["left leg"] == {1, 4, 7, 10}
    assert part_of["right leg"] == {2, 5, 8, 11}
    assert part_of["spine"] == {3, 6, 9}
    assert part_of["left arm"] == {13, 16, 18, 20}
    assert part_of["right arm"] == {14, 17, 19, 21}
    assert part_of["head"] == {12, 15}
    assert part_of["root"] == {0}
    # Through the pooling hierarchy (official groups) a limb part reads its joints via its own
    # intermediate nodes, which hold no joint of the other side; opposite-side joints reach it
    # only through the nodes shared with the other limb: root (0,1,2,3) and chest (9,6,12,13,14).
    shared = {HML_MID_ROOT, HML_MID_CHEST}
    for part, members, side in (("left leg", {1, 4, 7, 10}, "R"), ("right leg", {2, 5, 8, 11}, "L"),
                                ("left arm", {13, 16, 18, 20}, "R"), ("right arm", {14, 17, 19, 21}, "L")):
        p = names.index(part)
        own_nodes = [m for m in HML.pooling_levels[1][p] if m not in shared]
        own = set().union(*(HML.pooling_levels[0][m] for m in own_nodes))
        assert members <= own and not any(_side(HML, j) == side for j in own), part
    assert _part_joints(HML, names.index("left leg")) == {0, 1, 2, 3, 4, 7, 10}
    assert _part_joints(HML, names.index("left arm")) == {6, 9, 12, 13, 14, 16, 18, 20}
    assert _part_joints(HML, names.index("head")) == {6, 9, 12, 13, 14, 15}
    # every joint feeds at least one part
    assert set().union(*(_part_joints(HML, p) for p in range(len(names)))) == set(range(HML.num_joints))


@pytest.mark.parametrize("sk", BOTH, ids=lambda s: s.name)
def test_part_pooling_is_mirror_symmetric(sk):
    m = sk.mirror_map
    for p in range(len(PART_NAMES)):
        assert {m[j] for j in _part_joints(sk, p)} == _part_joints(sk, PART_MIRROR[p])
        assert {m[j] for j, q in enumerate(sk.joint_to_part) if q == p} == \
               {j for j, q in enumerate(sk.joint_to_part) if q == PART_MIRROR[p]}


@pytest.mark.parametrize("sk", BOTH, ids=lambda s: s.name)
def test_pool_matrices(sk):
    for level, n_in in enumerate((sk.num_joints, 12)):
        pool = sk.pool_matrix(level)
        assert pool.shape[1] == n_in
        np.testing.assert_allclose(pool.sum(1), 1.0, rtol=1e-6)
        np.testing.assert_array_equal(sk.unpool_matrix(level), (pool > 0).T.astype(np.float32))
        assert (pool.sum(0) > 0).all()   # no input node is dropped
    assert sk.pool_matrix(0).shape == (12, sk.num_joints) and sk.pool_matrix(1).shape == (7, 12)
    # the pooled graphs are trees over their nodes
    for edges, n in zip(sk.level_edges, (sk.num_joints, 12, 7)):
        assert len(edges) == n - 1 and {a for e in edges for a in e} == set(range(n))


def test_target_bone_lengths_match_real_data(sample_joints):
    parents = np.asarray(HML.parents[1:])
    lengths = np.linalg.norm(sample_joints[:, 1:] - sample_joints[:, parents], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(HML.bone_lengths[1:], lengths.shape), atol=2e-5)
    # frame 0 of processed data faces +Z with the left side at +x
    assert sample_joints[0, 1, 0] > sample_joints[0, 2, 0]


def test_unknown_skeleton_error_lists_known_names():
    with pytest.raises(ValueError) as err:
        get_skeleton("smplx")
    msg = str(err.value)
    assert "'smplx'" in msg
    for name in available_skeletons():
        assert name in msg
    with pytest.raises(TypeError, match="name or a Skeleton"):
        get_skeleton(3)
