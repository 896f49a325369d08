"""A small random forest for the online RF likelihood (Ko 2013, seed 000 sec. 4.3).

Ko 2013 refits 12 forests of 4 trees every learning frame on a memory of at most 45
examples of 8 features. scikit-learn's per-call overhead (about 10 ms per forest fit and
1 ms per predict) would spend the whole frame budget on 12 forests, so the trees are grown
here (bootstrap sample, m random features per node, best Gini split, depth <= max_depth),
all trees together one level per vectorised step, and stored as flat arrays: all trees
of all forests are evaluated for all particles at once, one vectorised step per level.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ptzd.vision.likelihood import FloatArray

IntArray = NDArray[np.intp]


class ForestBank:
    """Several independent random forests, each over its own slice of the feature vector.

    `groups` lists the (start, stop) feature columns each forest sees; `predict` returns
    P(positive) per forest: the mean leaf posterior of its trees (seed eqs. 15-16).
    """

    def __init__(
        self, groups: list[tuple[int, int]], trees: int, max_depth: int, features_per_node: int
    ) -> None:
        self.groups = groups
        self.trees = trees
        self.max_depth = max_depth
        self.features_per_node = features_per_node
        self._feature: IntArray = np.zeros((0, 1), np.intp)
        self._threshold: FloatArray = np.zeros((0, 1))
        self._left: IntArray = np.zeros((0, 1), np.intp)
        self._right: IntArray = np.zeros((0, 1), np.intp)
        self._value: FloatArray = np.zeros((0, 1))
        self.depth = 0

    @property
    def trained(self) -> bool:
        return bool(self._feature.shape[0] > 0)

    def fit(self, x: FloatArray, y: NDArray[np.bool_], rng: np.random.Generator) -> None:
        """Grow `trees` trees per forest on the rows of x (examples) and labels y.

        All trees grow together, one tree level per step: every open node of every tree
        finds its best split in one batched computation over (node, sample, feature).
        """
        n = y.shape[0]
        starts = np.repeat([g[0] for g in self.groups], self.trees)
        widths = np.repeat([g[1] - g[0] for g in self.groups], self.trees)
        count = starts.size
        width = 2 * n + 1  # a binary tree over n samples has at most 2n - 1 nodes
        self._feature = np.zeros((count, width), np.intp)
        self._threshold = np.zeros((count, width))
        self._left = np.tile(np.arange(width, dtype=np.intp), (count, 1))
        self._right = self._left.copy()
        self._value = np.zeros((count, width))
        sizes = np.ones(count, np.intp)  # nodes used per tree
        boot = rng.integers(0, n, size=(count, n))  # bootstrap sample per tree (Breiman)
        x_boot = x[boot]  # trees x n x F
        y_boot = y[boot].astype(np.float64)
        # open nodes: tree, node id, sample mask
        tree = np.arange(count)
        node = np.zeros(count, np.intp)
        mask = np.ones((count, n), bool)
        m = self.features_per_node
        depth = 0
        while tree.size:
            total = mask.sum(axis=1).astype(np.float64)
            pos = (y_boot[tree] * mask).sum(axis=1)
            self._value[tree, node] = np.where(total > 0, pos / np.maximum(total, 1), 0.5)
            can_split = (total >= 2) & (pos > 0) & (pos < total) & (depth < self.max_depth)
            tree, node, mask = tree[can_split], node[can_split], mask[can_split]
            total, pos = total[can_split], pos[can_split]
            if not tree.size:
                break
            k = tree.size
            # m distinct random features of the tree's group per node
            keys = rng.random((k, int(widths.max())))
            keys[np.arange(widths.max())[None, :] >= widths[tree][:, None]] = np.inf
            local = np.argsort(keys, axis=1)[:, : min(m, int(widths.min()))]
            feats = local + starts[tree][:, None]  # k x m
            cols = np.take_along_axis(x_boot[tree], feats[:, None, :], axis=2)  # k x n x m
            cols = np.where(mask[:, :, None], cols, np.inf)
            order = np.argsort(cols, axis=1, kind="stable")
            xs = np.take_along_axis(cols, order, axis=1)
            ys = np.take_along_axis(
                np.broadcast_to((y_boot[tree] * mask)[:, :, None], cols.shape), order, axis=1
            )
            left_pos = np.cumsum(ys, axis=1)[:, :-1]
            left_n = np.arange(1, n, dtype=np.float64)[None, :, None]
            right_n = total[:, None, None] - left_n
            pl = left_pos / left_n
            pr = (pos[:, None, None] - left_pos) / np.maximum(right_n, 1)
            gini = (left_n * 2 * pl * (1 - pl) + right_n * 2 * pr * (1 - pr)) / total[:, None, None]
            p = pos / total
            parent = (2 * p * (1 - p))[:, None, None]
            valid = np.isfinite(xs[:, 1:]) & (xs[:, 1:] > xs[:, :-1])
            gain = np.where(valid, parent - gini, -np.inf).reshape(k, -1)
            best = np.argmax(gain, axis=1)
            split = gain[np.arange(k), best] > 0
            i, j = np.unravel_index(best, (n - 1, feats.shape[1]))
            rows = np.arange(k)
            threshold = (xs[rows, i, j] + xs[rows, i + 1, j]) / 2
            feature = feats[rows, j]
            tree, node, mask = tree[split], node[split], mask[split]
            threshold, feature = threshold[split], feature[split]
            left_id = sizes[tree]
            right_id = left_id + 1
            sizes[tree] += 2
            self._feature[tree, node] = feature
            self._threshold[tree, node] = threshold
            self._left[tree, node] = left_id
            self._right[tree, node] = right_id
            goes_left = (
                x_boot[tree[:, None], np.arange(n)[None, :], feature[:, None]]
                <= (threshold[:, None])
            )
            tree = np.concatenate([tree, tree])
            node = np.concatenate([left_id, right_id])
            mask = np.concatenate([mask & goes_left, mask & ~goes_left])
            depth += 1
        self.depth = depth

    def predict(self, x: FloatArray) -> FloatArray:
        """P(positive) per example and forest: N x len(groups)."""
        if not self.trained:
            raise RuntimeError("fit() the forests first")
        count = self._feature.shape[0]
        n = x.shape[0]
        rows = np.arange(count)[:, None]
        node = np.zeros((count, n), np.intp)
        examples = np.arange(n)[None, :]
        for _ in range(self.depth):
            f = self._feature[rows, node]
            go_left = x[examples, f] <= self._threshold[rows, node]
            node = np.where(go_left, self._left[rows, node], self._right[rows, node])
        leaf = self._value[rows, node]  # trees x N
        per_forest: FloatArray = leaf.reshape(len(self.groups), self.trees, n).mean(axis=1).T
        return per_forest
