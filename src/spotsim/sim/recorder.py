"""The Python side of a run's record: the rows and replay snapshots each call of the compiled
loop wrote (`record.close_interval`), kept across welds and turned into named arrays."""

from __future__ import annotations

import numpy as np

from .record import REPLAY_RATE_HZ


class Recorder:
    """Keeps the rows and the replay's contact snapshots of a run.

    The model may change (a weld): the rows are laid out by the unwelded scene (`record.Layout`)
    and the snapshots name spheres and faces by their index in the first model.
    """

    def __init__(self, model):
        self.first = model
        self.layout = model.layout
        self.chunks: list[np.ndarray] = []  # rows, (n, layout.width) each
        self.face_names = model.face_names
        self.snapshots: dict[str, list] = {k: [] for k in (
            "row", "pairs", "master", "slave", "state", "faces_in_range", "force_W")}
        self._ids = (None, None)  # (model, its SphereIds in the first model)

    def collect(self, model, progress, near: np.ndarray) -> int:
        """Keep the rows and snapshots a call of the loop wrote (its `loop.Progress`), near:
        the broad phase's face pairs during the call. Returns the number of rows."""
        n_rows, n, k = progress.n_rows, progress.n_snapshots, progress.n_snapshot_pairs
        if n_rows:
            self.chunks.append(progress.rows[:n_rows].copy())
        if n:
            s = progress.snapshots
            self.add_snapshots(model, near, s.row[:n], s.pairs[:n], s.force_W[:n], s.master[:k], s.slave[:k],
                               s.state[:k])
        return n_rows

    def add_snapshots(self, model, near: np.ndarray, rows: np.ndarray, pairs: np.ndarray, force_W: np.ndarray,
                      master: np.ndarray, slave: np.ndarray, state: np.ndarray) -> None:
        """Keep what the replay draws at samples rows (n,): the pairs in contact (pairs (n,)
        of them at each; their master and slave spheres and states, all concatenated), the
        faces in contact range and each module's combined contact force, (n, n_modules, 3),
        world. near: the broad phase's face pairs, the same at all these samples."""
        if self._ids[0] is not model:
            self._ids = (model, SphereIds(model, self.first))
        ids = self._ids[1]
        s = self.snapshots
        in_range = np.zeros((len(rows), len(self.face_names[0]) + len(self.face_names[1])), dtype=bool)
        # coal's face pairs within the security margin (the last broad phase's)
        in_range[:, ids.pair_faces[np.asarray(near, dtype=np.int64)].ravel()] = True
        sample = np.repeat(np.arange(len(rows)), pairs)
        in_range[sample, ids.master_face[model.master.face[master]]] = True
        in_range[sample, ids.slave_face[model.slave.face[slave]]] = True
        s["master"].append(ids.master[master].astype(np.int32))
        s["slave"].append(ids.slave[slave].astype(np.int32))
        s["state"].append(state.astype(np.int8))
        s["row"].append(np.asarray(rows, dtype=np.int64).copy())
        s["pairs"].append(np.asarray(pairs, dtype=np.int64).copy())
        s["faces_in_range"].append(in_range)
        s["force_W"].append(np.array(force_W, dtype=float))

    def arrays(self) -> dict[str, np.ndarray]:
        rows = np.concatenate(self.chunks) if self.chunks else np.zeros((0, self.layout.width))
        return self.layout.split(rows)

    def replay_arrays(self) -> dict[str, np.ndarray]:
        """The snapshots as the arrays of replay.npz (pairs of all snapshots concatenated)."""
        s = self.snapshots
        n_faces = len(self.face_names[0]) + len(self.face_names[1])
        cat = {k: np.concatenate(s[k]) if s[k] else np.zeros(shape, dtype) for k, shape, dtype in (
            ("master", 0, np.int32), ("slave", 0, np.int32), ("state", 0, np.int8), ("row", 0, np.int64),
            ("pairs", 0, np.int64), ("faces_in_range", (0, n_faces), bool),
            ("force_W", (0, len(self.first.modules), 3), float))}
        return {
            "rate_hz": np.float64(REPLAY_RATE_HZ),
            "row": cat["row"],
            "pairs_end": np.cumsum(cat["pairs"], dtype=np.int64),
            **{k: cat[k] for k in ("master", "slave", "state", "faces_in_range", "force_W")},
            "master_faces": np.asarray(self.face_names[0]),
            "slave_faces": np.asarray(self.face_names[1]),
        }


class SphereIds:
    """Where a model's spheres and faces sit in the first model's layers (found by face name).

    A weld rebuilds the scene without the welded pair's faces; the faces left keep their
    spheres, in the same order on the same joint frames.
    master, slave: (n,) first-model index of each sphere. master_face, slave_face: first-model
    face index of each face, the slave faces numbered after the master ones. pair_faces:
    (n_face_pairs, 2) the two faces of each of the model's face pairs, so numbered.
    """

    def __init__(self, model, first):
        names, first_names = model.face_names, first.face_names
        offsets = (0, len(first_names[0]))
        maps = []
        for role, layers, first_layers in ((0, model.master, first.master), (1, model.slave, first.slave)):
            face = np.array([first_names[role].index(n) for n in names[role]], dtype=np.int64)
            start = np.searchsorted(layers.face, np.arange(len(names[role])))
            first_start = np.searchsorted(first_layers.face, np.arange(len(first_names[role])))
            local = np.arange(len(layers.face)) - start[layers.face]
            maps.append((first_start[face[layers.face]] + local, face + offsets[role]))
        (self.master, self.master_face), (self.slave, self.slave_face) = maps
        table = model.sim.faces
        self.pair_faces = np.stack([self.master_face[model.master.face[table.master_start]],
                                    self.slave_face[table.slave_face]], axis=1).reshape(-1, 2)
