"""Settings of the dense-offset matcher (:func:`~jaxgrav.match.dense.match_dense`)."""

import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import concrete
from jaxgrav.match.scoring import SCORES

__all__ = ["DenseConfig"]


@pytree_dataclass
class DenseConfig:
    """Settings of the dense-offset matcher.

    Attributes
    ----------
    spacing_m : float
        Spacing of the offset grid (m).
    region : {"square", "disc"}
        The searched offsets (static): the whole square lattice of
        ``(2·half_size + 1)²`` offsets (paper A's window), or only those within the
        disc of radius ``half_size · spacing_m`` about the INS track. The window's
        half-side is sized from a drift *radius* (:func:`~jaxgrav.match.sizing.config_for`),
        so the square's corners, up to √2 × that radius away, are offsets the INS
        error cannot reach; with ``"disc"`` they are not candidates, the refined
        offset is clamped to the disc and the posterior is taken over it (a uniform
        prior over the disc instead of the square).
    max_rotation_deg : float
        Largest heading error tried (degrees); rotations are spread evenly over
        ±max_rotation_deg.
    weight_decay : float
        μ_i = exp(−decay · i/(N−1)).
    noise_mgal : float
        Reading noise σ_n (mGal), used with ``bias_sigma_mgal``.
    bias_sigma_mgal : float
        Prior σ_b of the common bias (mGal) for ``score="bias"``; ``inf`` (default)
        estimates it freely, see :mod:`~jaxgrav.match.scoring`.
    damping : float
        Levenberg–Marquardt damping of the refinement (relative to the diagonal).
    half_size : int
        Offsets per side (static): ``(2·half_size + 1)²`` offsets, covering
        ±half_size·spacing_m (with ``region="disc"`` those within that radius).
    n_rotations : int
        Heading errors tried (static; 1 = none, and the refinement keeps heading fixed).
    refine_steps : int
        Gauss–Newton steps after the grid search (static; 0 = none).
    k_best : int
        Candidates ranked before selection (static).
    method : {"bicubic", "bilinear"}
        Map interpolation (static); the refinement needs bicubic's smooth gradient.
    score : {"bias", "difference", "absolute"}
        Score form (static), see :mod:`~jaxgrav.match.scoring`.
    selection : {"best", "nearest"}
        Least score, or paper A's nearest-to-INS rule among the k best (static).
    lattice_block : int
        Map nodes per axis of the block from which each fix's offset lattice is
        evaluated separably (static; cost grows with it). Used when the offsets
        span at most ``lattice_block − 2`` map cells per axis (checked at run time
        from ``spacing_m`` and the map; the default 6 covers ±half_size·spacing_m up
        to 2 cells); otherwise a block of ``2·half_size + 2`` nodes, which fits
        whenever ``spacing_m`` is at most the node spacing; otherwise, or with 0,
        every shifted fix is sampled on its own (same values, slowest).
    spacing_bound_m : float or None
        The largest ``spacing_m`` the config will be run with, known when compiling
        (static; None, the default: any). With it the block sizes are chosen for it:
        a larger block or the point-by-point path that no spacing up to it can need is
        not compiled (the same values; a smaller program and, under ``vmap`` with a
        spacing per track, less work). ``spacing_m`` must not exceed it (checked when
        concrete), as :class:`~jaxgrav.navigate.LooseConfig`'s loop guarantees.
    map_error_mgal : float
        σ of the map's error (mGal). 0 (default): the white-noise score, exactly as
        without this field; > 0: candidates are scored by the GLS likelihood with
        covariance ``σ_n² I + C_map`` along the track (:mod:`~jaxgrav.match.gls`,
        the bias marginalised; ``score="absolute"`` has no bias, ``"difference"``
        a flat-prior one), the refinement whitened the same way. Either way the
        refined offset is clamped to the searched region. Traced: changing it never
        recompiles.
    map_error_length_m : float
        Correlation length L of the map error (m), traced.
    map_error_order : {1, 2}
        Gauss–Markov order of the map-error covariance (static), as
        :class:`~jaxgrav.fields.map_error.CorrelatedMapError`'s family.
    score_model : {"auto", "white", "gls"}
        Which score is compiled (static). ``"auto"`` (default): the white-noise score
        always, and the GLS one in a branch taken when ``map_error_mgal > 0`` at run
        time, so a sweep of σ through 0 never recompiles. ``"white"``: only the
        white-noise score (``map_error_mgal`` must be 0); ``"gls"``: only the GLS score
        (σ = 0 then gives the white-noise likelihood to rounding). Either compiles in
        about half to two thirds of the time of ``"auto"`` (the run time measured the
        same within noise). :func:`~jaxgrav.match.sizing.config_for` sets ``"white"``
        or ``"gls"`` from its ``map_error``.
    gap_fixes : int
        Missing (NaN) map nodes (static). 0 (default): they are land, a candidate
        track with a fix in a cell that has a missing corner is dropped. > 0: they
        are survey gaps, a candidate is scored on its fixes over present cells and
        each fix over a missing cell adds the χ² it is expected to add (1), so that
        candidates compare on one scale (:mod:`~jaxgrav.match.gaps`); a candidate
        with more than ``gap_fixes`` such fixes is dropped. Needs the point path
        (the separable lattice is not used then).
    fix : {"best", "posterior"}
        The returned offset (static): the refined best candidate, or the
        likelihood-weighted posterior mean over all offsets (the refined best when
        the posterior is unresolved, see ``resolved_n_effective``).
    resolved_n_effective : float
        The posterior is resolved by the offset grid when ``n_effective`` reaches this;
        otherwise the covariance is the Gauss–Newton (Laplace) one.
    reading_covariance : Array or None
        Added to the GLS covariance of readings minus map, shape ``(N, N)`` (mGal²;
        traced): a reading error known only in distribution, e.g. the loosely coupled
        loop's Eötvös and segment-stretch error, linear in the INS error state
        (:func:`~jaxgrav.navigate.loose_match.segment_error_covariance`). Used by the
        GLS score only (``map_error_mgal`` > 0 or ``score_model="gls"``); None (default):
        nothing added.
    reading_coupling : Array or None
        Shape ``(N, 2)`` (mGal per m; traced): the readings' error expected for an offset
        (north, east), subtracted from each candidate's residuals in the grid search's
        GLS score (a nuisance correlated with the offset, as the loop's Eötvös error is
        with its position error; not in the refinement). None (default): nothing.
    offset_prior_m2 : Array or None
        A Gaussian prior on the offset, its 2 × 2 covariance (m², north/east; traced)
        about the searched track: the fix is then the posterior of the likelihood times
        this prior (:func:`~jaxgrav.match.integrity.fix_quality`), as the loosely coupled
        loop uses it with its filter's covariance. None (default): a flat prior over
        the searched offsets.
    max_sigma_m, max_second_mode, max_chi2_per_dof, max_edge_mass : float
        Integrity thresholds (traced): the fix is rejected (INS track returned,
        status 512, 1024, 2048, 4096) when the largest σ of its covariance (m), the
        second-mode likelihood ratio, the refined best χ² per degree of freedom or
        the posterior mass on the outermost offsets exceeds it. Defaults ``inf``:
        every found fix is accepted.
    max_sigma_ratio : float
        Also rejected (status 512) when the largest σ exceeds this fraction of the
        1-σ of a uniform prior over the searched region
        (:func:`~jaxgrav.match.integrity.region_sigma`): the readings did not narrow
        the search enough for a fix, whatever the region's size (traced; ``inf``,
        the default, never rejects).
    max_p_worse : float
        The no-harm test: also rejected (status 131072) when the probability, under the
        fix's Gaussian ``N(fix, covariance_m2)``, that the truth lies nearer the searched
        (INS) track than the fix exceeds this
        (:func:`~jaxgrav.match.integrity.p_worse_than_ins`; in ``[0, 0.5]`` or ``inf``,
        the default: never rejects). The entropy+ICCP matcher's test
        (``IccpConfig.max_p_worse``), the same rule.
    """

    spacing_m: float = 500.0
    region: str = static_field("square")
    max_rotation_deg: float = 2.0
    weight_decay: float = 0.0
    noise_mgal: float = 1.0
    bias_sigma_mgal: float = float("inf")
    damping: float = 1e-3
    half_size: int = static_field(10)
    n_rotations: int = static_field(1)
    refine_steps: int = static_field(8)
    k_best: int = static_field(5)
    method: str = static_field("bicubic")
    score: str = static_field("bias")
    selection: str = static_field("best")
    lattice_block: int = static_field(6)
    map_error_mgal: float = 0.0
    map_error_length_m: float = 10000.0
    map_error_order: int = static_field(2)
    score_model: str = static_field("auto")
    gap_fixes: int = static_field(0)
    fix: str = static_field("best")
    resolved_n_effective: float = 3.0
    max_sigma_m: float = float("inf")
    max_sigma_ratio: float = float("inf")
    max_second_mode: float = float("inf")
    max_chi2_per_dof: float = float("inf")
    max_edge_mass: float = float("inf")
    max_p_worse: float = float("inf")
    reading_covariance: object = None
    offset_prior_m2: object = None
    reading_coupling: object = None
    spacing_bound_m: float | None = static_field(None)

    def __post_init__(self):
        if self.region not in ("square", "disc"):
            raise ValueError(f"region must be 'square' or 'disc'; got {self.region!r}")
        if self.fix not in ("best", "posterior"):
            raise ValueError(f"fix must be 'best' or 'posterior'; got {self.fix!r}")
        if self.map_error_order not in (1, 2):
            raise ValueError(f"map_error_order must be 1 or 2; got {self.map_error_order!r}")
        if self.score_model not in ("auto", "white", "gls"):
            raise ValueError(f"score_model must be 'auto', 'white' or 'gls'; got "
                             f"{self.score_model!r}")
        for name in ("map_error_mgal", "map_error_length_m"):
            arr = concrete(getattr(self, name))
            if arr is not None and arr.dtype != object and not (
                    np.all(np.isfinite(arr)) and np.all(arr >= 0)):
                raise ValueError(f"{name} must be finite and >= 0; got {arr}")
        ratio = concrete(self.max_sigma_ratio)
        if ratio is not None and ratio.dtype != object and not np.all(ratio >= 0):
            raise ValueError(f"max_sigma_ratio must be >= 0 (inf: no test); got {ratio}")
        worse = concrete(self.max_p_worse)
        if worse is not None and worse.dtype != object and not np.all(
                (worse >= 0) & ((worse <= 0.5) | np.isposinf(worse))):
            raise ValueError(f"max_p_worse must be in [0, 0.5] (a probability; inf: no test); "
                             f"got {worse}")
        sigma = concrete(self.map_error_mgal)
        if (self.score_model == "white" and sigma is not None and sigma.dtype != object
                and np.any(sigma > 0)):
            raise ValueError(f"score_model='white' ignores the map error; got map_error_mgal="
                             f"{sigma} (use 'gls' or 'auto')")
        if isinstance(self.score, str) and self.score not in SCORES:
            raise ValueError(f"score must be one of {SCORES}; got {self.score!r}")
        if isinstance(self.n_rotations, int) and self.n_rotations < 1:
            raise ValueError(f"n_rotations must be >= 1; got {self.n_rotations!r}")
        if isinstance(self.lattice_block, int) and self.lattice_block < 0:
            raise ValueError(f"lattice_block must be >= 0; got {self.lattice_block!r}")
        if isinstance(self.gap_fixes, int) and self.gap_fixes < 0:
            raise ValueError(f"gap_fixes must be >= 0; got {self.gap_fixes!r}")
        bound = self.spacing_bound_m
        if bound is not None:
            if not (isinstance(bound, int | float) and bound > 0):
                raise ValueError(f"spacing_bound_m must be None or a number > 0 (static); got "
                                 f"{bound!r}")
            spacing = concrete(self.spacing_m)
            if spacing is not None and spacing.dtype != object and np.any(spacing > bound):
                raise ValueError(f"spacing_m must not exceed spacing_bound_m = {bound}; got "
                                 f"{spacing}")
