"""AMCL's parts replayed on cases recorded from Nav2 Humble's nav2_amcl (`twin nav conformance`).

Four components, each a checker `(meta, arrays, native) -> differences` (empty: equal), registered in
`twin.nav.conformance.COMPONENTS`:

- `amcl_motion_model`: `odometry_update` on the case's particles, odometry pose and change, alphas
  and the standard normal draws Nav2's `pf_ran_gaussian` consumed (per particle rot1, trans, rot2).
  The C kernel must be bitwise equal: it does Nav2's operations in Nav2's order with the same libm.
  The numpy path is held to 1e-12 m / rad per coordinate: numpy's own sin, cos and atan2 may round
  a last bit differently from libm's (it differs by up to 2e-14 on the recorded cases).
- `amcl_likelihood_field`: the map's distances (`nav2_distances`, bitwise against the SHA-256 of
  Nav2's `occ_dist`) and each particle's weight after `LikelihoodFieldModel::sensorFunction`,
  before normalisation, and their total (what the weights are divided by), bitwise on both paths:
  pz per cell is Nav2's formula with libm's exp, the cubes are `pz * pz * pz` added to 1 beam by
  beam, the total is summed in particle order, and the cell of an endpoint within 1e-6 of a cell
  edge is computed with Nav2's own arithmetic (elsewhere the cheaper lookup lands in the same cell).
- `amcl_resample`: `kld_resample` (pf_update_resample without recovery: w_diff is 0 in every case, as
  with TurtleBot3's recovery alphas of 0) on the case's particles and weights, given the uniforms
  Nav2's `drand48` returned. Nav2 draws two per sample, the first deciding on a random pose, the
  second the pick; the twin is given the second ones (and more after them, so a twin that drew past
  Nav2's stop would show). Equal means the same number of samples and each sample's pose bitwise.
- `amcl_estimate`: `cluster_estimate` on a particle set: the published cluster's mean (x, y, yaw)
  and the set's covariance (xx, xy, yx, yy, yaw) as `amcl_pose` carries them. The C kernel bitwise;
  the numpy path within 1e-12 (numpy's sin and cos).
"""

from __future__ import annotations

import hashlib
import itertools
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.nav.amcl._native import load_kernel
from twin.nav.amcl.filter import (
    Amcl,
    LikelihoodField,
    beam_endpoints,
    cluster_estimate,
    kld_limits,
    kld_resample,
    laser_likelihood,
    odometry_update,
    weight_total,
)
from twin.nav.frames import LaserGeometry
from twin.nav.map_server.map_io import OccupancyMap
from twin.nav.params import AmclParams

__all__ = [
    "RecordedDraws",
    "RunDraws",
    "check_amcl_estimate",
    "check_amcl_likelihood_field",
    "check_amcl_motion_model",
    "check_amcl_resample",
    "check_amcl_run",
]

Arrays = Mapping[str, NDArray[Any]]

MOTION_TOLERANCE_PYTHON = 1e-12
"""Largest difference (m, rad) in a particle coordinate after the numpy path's motion model (C: none)."""

RUN_TOLERANCE_PYTHON = 1e-9
"""Largest difference (m, rad, weight) on a recorded run's stored particle sets for the numpy path (C: none)."""


class RecordedDraws:
    """A draw source replaying recorded numbers: standard normals in order, uniforms in order.

    Raises `ValueError` when asked for more than was recorded, or for draws it does not hold.
    """

    def __init__(self, normals: NDArray[np.float64] | None = None, uniforms: NDArray[np.float64] | None = None):
        self._normals = np.zeros(0) if normals is None else np.asarray(normals, dtype=np.float64).ravel()
        self._uniforms = np.zeros(0) if uniforms is None else np.asarray(uniforms, dtype=np.float64).ravel()
        self.normals_used = 0
        self.uniforms_used = 0

    def standard_normal(self, size: Any) -> NDArray[np.float64]:
        """The next recorded standard normals, in the shape asked."""
        n = int(np.prod(size))
        if self.normals_used + n > len(self._normals):
            msg = f"asked for {n} normal draws, {len(self._normals) - self.normals_used} recorded ones left"
            raise ValueError(msg)
        out = self._normals[self.normals_used : self.normals_used + n].reshape(size)
        self.normals_used += n
        return out

    def random(self, size: Any) -> NDArray[np.float64]:
        """The next recorded uniforms in [0, 1), in the shape asked."""
        n = int(np.prod(size))
        if self.uniforms_used + n > len(self._uniforms):
            msg = f"asked for {n} uniform draws, {len(self._uniforms) - self.uniforms_used} recorded ones left"
            raise ValueError(msg)
        out = self._uniforms[self.uniforms_used : self.uniforms_used + n].reshape(size)
        self.uniforms_used += n
        return out

    def integers(self, low: Any, high: Any, size: Any) -> NDArray[np.int64]:
        """Not recorded: the cases replay no uniform pose draws."""
        raise ValueError("no recorded integer draws")

    def uniform(self, low: Any, high: Any, size: Any) -> NDArray[np.float64]:
        """Not recorded: the cases replay no uniform pose draws."""
        raise ValueError("no recorded uniform pose draws")


def _native_missing(native: bool) -> list[str]:
    if native and load_kernel() is None:
        return ["the C kernel is not available (no C compiler?): only the Python path can be checked"]
    return []


def _first_particle(got: NDArray[np.float64], want: NDArray[np.float64], bad: NDArray[np.bool_], what: str) -> str:
    rows = np.flatnonzero(bad.reshape(len(want), -1).any(axis=1))
    i = int(rows[0])
    first = f"first {i}: twin {got[i].tolist()!r}, Nav2 {want[i].tolist()!r}"
    return f"{what}: {len(rows)} of {len(want)} particles differ, {first}"


def check_amcl_motion_model(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The ways the twin's differential motion model differs from Nav2's on one case (`amcl_cases/README.md`)."""
    if missing := _native_missing(native):
        return missing
    draws = RecordedDraws(normals=arrays["normals"])
    pose = tuple(float(v) for v in meta["pose"])
    delta = tuple(float(v) for v in meta["delta"])
    alphas = tuple(float(v) for v in meta["alphas"][:4])
    got = odometry_update(arrays["poses"].copy(), pose, delta, alphas, draws, native=native)  # type: ignore[arg-type]
    want = arrays["poses_after"]
    out: list[str] = []
    if draws.normals_used != meta["draws_used"]:
        out.append(f"the twin used {draws.normals_used} normal draws, Nav2 {meta['draws_used']}")
    if got.shape != want.shape:
        return [*out, f"poses: shape {got.shape}, Nav2 {want.shape}"]
    tolerance = 0.0 if native else MOTION_TOLERANCE_PYTHON
    bad = ~(np.abs(got - want) <= tolerance)
    if bad.any():
        out.append(_first_particle(got, want, bad, f"poses (beyond {tolerance:g})"))
    return out


def _case_map(meta: Mapping[str, Any], arrays: Arrays) -> OccupancyMap:
    """The case's map as AMCL receives it (its OccupancyGrid's resolution, origin and cells)."""
    return OccupancyMap(
        resolution_m=float(meta["resolution"]),
        origin_x_m=float(meta["origin"][0]),
        origin_y_m=float(meta["origin"][1]),
        data=arrays["map"].astype(np.int8),
    )


def check_amcl_likelihood_field(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The ways the twin's likelihood-field model differs from Nav2's on one case (`amcl_cases/README.md`)."""
    if missing := _native_missing(native):
        return missing
    occupancy = _case_map(meta, arrays)
    field = LikelihoodField(occupancy, float(meta["laser_likelihood_max_dist"]), native=native)
    out: list[str] = []
    digest = hashlib.sha256(np.ascontiguousarray(field.distance_m, dtype="<f8").tobytes()).hexdigest()
    if digest != meta["occ_dist_sha256"]:
        out.append("the likelihood field's distances differ from Nav2's occ_dist (their SHA-256)")
    range_max = float(meta["range_max"])
    pz = field.pz(float(meta["z_hit"]), float(meta["z_rand"]), float(meta["sigma_hit"]), range_max)
    max_beams = int(meta["max_beams"])
    weights = arrays["weights"]
    want = arrays["weights_after"]
    if max_beams < 2:  # Nav2 refuses to weigh (sensorUpdate returns false): weights unchanged
        got = weights.copy()
        if meta["updated"]:
            out.append("Nav2 weighed the particles with fewer than two beams; the twin does not")
    else:
        laser = meta["laser_pose"]
        beams = beam_endpoints(arrays["ranges"], arrays["bearings"], (laser[0], laser[1]), range_max, max_beams)
        if laser[2] != 0.0:
            return [*out, "a laser pose with a yaw (Nav2 sets it to 0 and turns the bearings instead)"]
        got = weights * laser_likelihood(arrays["poses"], beams, field, pz, native=native)
    bad = got != want
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        out.append(
            f"weights: {int(bad.sum())} of {len(want)} particles differ, first {i}: twin {got[i]!r}, Nav2 {want[i]!r}"
        )
    elif meta["updated"] and (total := weight_total(got)) != meta["total_weight"]:
        out.append(f"total weight (pf_update_sensor divides by it): twin {total!r}, Nav2 {meta['total_weight']!r}")
    return out


def check_amcl_resample(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The ways the twin's KLD resampling differs from Nav2's on one case (`amcl_cases/README.md`)."""
    if missing := _native_missing(native):
        return missing
    if meta["w_slow"] > 0.0 and 1.0 - meta["w_fast"] / meta["w_slow"] > 0.0:
        return ["a case with recovery draws (w_diff > 0): the twin checks resampling without them"]
    m = int(meta["max_particles"])
    picks = np.full(m, 0.5)  # past Nav2's stop: a twin drawing on would take these
    recorded = arrays["uniforms"][1::2][:m]
    picks[: len(recorded)] = recorded
    limits = kld_limits(int(meta["min_particles"]), m, float(meta["pf_err"]), float(meta["pf_z"]))
    got = kld_resample(arrays["poses"], arrays["weights"], picks, limits, native=native)
    want = arrays["poses_after"]
    if got.shape != want.shape:
        return [f"samples: the twin kept {len(got)}, Nav2 {len(want)}"]
    bad = got != want
    if bad.any():
        return [_first_particle(got, want, bad, "samples")]
    return []


def check_amcl_estimate(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The ways the twin's published pose and covariance differ from Nav2's on one case (`amcl_cases/README.md`)."""
    if missing := _native_missing(native):
        return missing
    mean, cov = cluster_estimate(arrays["poses"], arrays["weights"], native=native)
    tolerance = 0.0 if native else MOTION_TOLERANCE_PYTHON
    out: list[str] = []
    for name, got, want in zip(("x", "y", "yaw"), mean, meta["mean"], strict=True):
        if not abs(got - want) <= tolerance:
            out.append(f"published {name}: twin {got!r}, Nav2 {want!r} (cluster {meta['published_cluster']})")
    want_cov = meta["covariance"]
    for name, got in (("xx", cov[0, 0]), ("xy", cov[0, 1]), ("yx", cov[1, 0]), ("yy", cov[1, 1]), ("yaw", cov[2, 2])):
        if not abs(float(got) - want_cov[name]) <= tolerance * max(1.0, abs(want_cov[name])):
            out.append(f"covariance {name}: twin {float(got)!r}, Nav2 {want_cov[name]!r}")
    return out


class RunDraws:
    """The draws of a recorded run: standard normals in order; per resampling, Nav2's picks.

    Nav2 draws two uniforms per resampled sample (the recovery test, then the pick) and stops at KLD's
    bound; the twin asks for `max_particles` picks at once. Each `random` call gets the next resampling's
    recorded picks and 0.5 after them, past Nav2's stop.
    """

    def __init__(self, normals: NDArray[Any], picks: NDArray[Any], per_update: NDArray[np.int64]) -> None:
        self._normals = RecordedDraws(normals=np.asarray(normals, dtype=np.float64))
        bounds = np.cumsum(np.concatenate([[0], per_update])).astype(np.int64)
        u = np.asarray(picks, dtype=np.float64)
        self._picks = [u[a:b] for a, b in itertools.pairwise(bounds) if b > a]  # resamplings only
        self.resamplings = 0

    @property
    def normals_used(self) -> int:
        """Standard normals handed out so far."""
        return self._normals.normals_used

    def standard_normal(self, size: Any) -> NDArray[np.float64]:
        """The next recorded standard normals, in the shape asked."""
        return self._normals.standard_normal(size)

    def random(self, size: Any) -> NDArray[np.float64]:
        """The next resampling's picks, then 0.5 up to `size`."""
        if self.resamplings >= len(self._picks):
            raise ValueError(f"asked for a resampling's draws, {len(self._picks)} recorded")
        picks = self._picks[self.resamplings]
        self.resamplings += 1
        n = int(np.prod(size))
        out = np.full(n, 0.5)
        out[: min(n, len(picks))] = picks[:n]
        return out.reshape(size)

    def integers(self, low: Any, high: Any, size: Any) -> NDArray[np.int64]:
        """Not recorded: the run has no recovery draws."""
        raise ValueError("no recorded integer draws")

    def uniform(self, low: Any, high: Any, size: Any) -> NDArray[np.float64]:
        """Not recorded: the run has no recovery draws."""
        raise ValueError("no recorded uniform pose draws")


def _set_digest(poses: NDArray[np.float64], weights: NDArray[np.float64]) -> str:
    rows = np.column_stack([poses, weights])
    return hashlib.sha256(np.ascontiguousarray(rows, dtype="<f8").tobytes()).hexdigest()


class _Watched(Amcl):
    """The twin's filter, keeping the set as the laser model leaves it (weights normalised, before resampling)."""

    weighed: tuple[NDArray[np.float64], NDArray[np.float64]] = (np.zeros((0, 3)), np.zeros(0))

    def _sensor(self, ranges: NDArray[np.float64]) -> None:
        super()._sensor(ranges)
        self.weighed = (self.poses.copy(), self.weights.copy())


def _compare_set(
    got_set: tuple[NDArray[np.float64], NDArray[np.float64]],
    arrays: Arrays,
    i: int,
    *,
    stored: set[int],
    key: str,
    tolerance: float,
) -> str:
    """How a particle set differs from Nav2's at update i ('' when equal): count, SHA-256 (bitwise), stored set."""
    poses, weights = got_set
    count = int(arrays[f"{key}_count"][i])
    if len(poses) != count:
        return f"{len(poses)} particles, Nav2 {count}"
    got = np.column_stack([poses, weights])
    want = arrays[f"{key}_{i:03d}"] if i in stored else None
    if tolerance == 0.0 and _set_digest(poses, weights) != str(arrays[f"{key}_sha256"][i]):
        if want is None:
            return "the particle set differs from Nav2's (SHA-256)"
        bad = got != want
        return _first_particle(got, want, bad, "particles (x, y, yaw, weight)") if bad.any() else "SHA-256 differs"
    if want is not None:
        bad = ~(np.abs(got - want) <= tolerance)
        if bad.any():
            return _first_particle(got, want, bad, f"particles (x, y, yaw, weight; beyond {tolerance:g})")
    return ""


def check_amcl_run(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The first update at which the twin's filter leaves Nav2's on a recorded run (`amcl_run_cases/README.md`).

    The twin's `Amcl` is started from the recorded initial particles and fed every scan (odometry
    pose, ranges) with Nav2's draws; at each update (the same scans as Nav2's gating) the particle set
    and weights must equal Nav2's (bitwise for the C kernel: SHA-256 of every set, and the stored
    sets; within 1e-9 m / rad for the numpy path, on the stored sets), and so must `w_slow` and
    `w_fast` and the published pose and covariance. Stops at the first update that differs.
    """
    if missing := _native_missing(native):
        return missing
    occupancy = _case_map(meta, arrays)
    params = AmclParams(**meta["params"])
    draws = RunDraws(arrays["normals"], arrays["uniforms"], arrays["update_uniforms"])
    amcl = _Watched(params, occupancy, LaserGeometry(**meta["laser"]), draws, native=native)
    amcl.set_particles(arrays["initial_poses"])
    tolerance = 0.0 if native else RUN_TOLERANCE_PYTHON
    updates = {int(s): i for i, s in enumerate(arrays["update_scan"])}
    stored = {int(i) for i in meta["stored_sets"]}
    for s, (odom, ranges) in enumerate(zip(arrays["odom"], arrays["ranges"], strict=True)):
        estimate = amcl.process_scan((float(odom[0]), float(odom[1]), float(odom[2])), ranges)
        i = updates.get(s)
        if i is None:
            if amcl.updated:
                return [f"scan {s}: the twin updated the filter, Nav2 did not"]
            continue
        where = f"update {i} (scan {s})"
        if not amcl.updated:
            return [f"{where}: Nav2 updated the filter, the twin did not"]
        if differ := _compare_set(amcl.weighed, arrays, i, stored=stored, key="weighed", tolerance=tolerance):
            return [f"{where}, after the motion and laser models: {differ}"]
        if differ := _compare_set((amcl.poses, amcl.weights), arrays, i, stored=stored, key="set", tolerance=tolerance):
            return [f"{where}, after resampling: {differ}"]
        for name, got, want in (
            ("w_slow", amcl.w_slow, arrays["w_slow"][i]),
            ("w_fast", amcl.w_fast, arrays["w_fast"][i]),
        ):
            if not abs(got - float(want)) <= tolerance * abs(float(want)):
                return [f"{where}: {name} (the running average of the weights): twin {got!r}, Nav2 {float(want)!r}"]
        if estimate is None or not arrays["published"][i]:
            if estimate is not None or arrays["published"][i]:
                who = "the twin" if estimate is not None else "Nav2"
                return [f"{where}: only {who} published a pose (amcl_pose)"]
            continue
        cov = estimate.covariance
        got_pose = (estimate.x_m, estimate.y_m, estimate.yaw_rad, cov[0, 0], cov[0, 1], cov[1, 0], cov[1, 1], cov[2, 2])
        want_pose = [*arrays["pose"][i], *arrays["covariance"][i]]
        names = ("x", "y", "yaw", "covariance xx", "covariance xy", "covariance yx", "covariance yy", "covariance yaw")
        for name, g, w in zip(names, got_pose, want_pose, strict=True):
            if not abs(float(g) - float(w)) <= tolerance * max(1.0, abs(float(w))):
                return [f"{where}: published {name}: twin {float(g)!r}, Nav2 {float(w)!r}"]
    if draws.normals_used != int(meta["normals_used"]):
        return [f"the twin used {draws.normals_used} normal draws, Nav2 {meta['normals_used']}"]
    resamplings = int(np.count_nonzero(arrays["update_uniforms"]))
    if draws.resamplings != resamplings:
        return [f"the twin resampled {draws.resamplings} times, Nav2 {resamplings}"]
    return []
