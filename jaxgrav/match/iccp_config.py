"""Settings of the ICCP matcher (:class:`IccpConfig`), of ICCP alone and of its combined use."""

import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import concrete

__all__ = ["WEIGHTS", "IccpConfig"]

WEIGHTS = ("uniform", "gradient")


@pytree_dataclass
class IccpConfig:
    """Settings of the ICCP matcher.

    Attributes
    ----------
    window_m : float
        Sliding-window radius (m): a contour point farther than this from its current
        point is not used.
    max_step_m : float
        Longest single Newton step (m).
    contour_tol : float
        Largest ``|f(x) − z|`` (map units) of a usable contour point.
    tol_m : float
        Convergence: largest point movement in one iteration (m).
    max_rotation_deg : float
        Bound on the rotation about the centroid (degrees): the INS heading-error
        bound (default 90, i.e. none that matters).
    noise : float
        Reading noise σ, plus map error (map units); used by the combined matcher's
        acceptance test only.
    accept_chi2 : float
        The combined matcher replaces the coarse track by the fine one only if
        ``N·(misfit_coarse − misfit_fine)/σ² ≥ accept_chi2``: default 7.81, the 95 %
        point of χ² with 3 degrees of freedom, i.e. the coarse offset lies outside the
        fine transform's 95 % confidence region. With ``noise = 0``: any decrease.
    max_iter : int
        Iterations (static).
    newton_steps : int
        Newton projection steps per iteration (static).
    refine_steps : int
        Least-squares refinement after ICCP (static, default 0 = ICCP only):
        Levenberg–Marquardt steps on the misfit ``mean((z − f(R p + t))²)`` itself
        over ``(θ, t)`` with the same rotation bound, accepted only when they lower it.
    weights : {"uniform", "gradient"}
        Kabsch weights of usable contour points (static): equal (the paper), or
        ``|∇f|²`` at the contour point, the inverse variance of its position along
        the gradient under reading noise.
    method : {"bicubic"}
        Map interpolation (static); projection needs a smooth gradient.
    map_error_mgal, map_error_length_m, map_error_order, fix, resolved_n_effective, max_*
        :func:`~jaxgrav.match.combined.match_entropy_iccp` only (its docstring): map error
        σ (map units), L (m) of its GLS score (σ = 0: white ``noise``), the coarse fix
        (entropy's, or the GLS posterior mean), integrity thresholds (status 512–4096).
    region : {"square", "disc"}
        :func:`~jaxgrav.match.combined.match_entropy_iccp` only (static): the support of
        the GLS posterior over the entropy stage's offsets, every offset of the square
        grid (default) or those within the disc of its half-side
        (:func:`~jaxgrav.match.integrity.region_mask`: the INS error is bounded by a
        radius, the square's corners lie beyond it).
    max_sigma_ratio : float
        :func:`~jaxgrav.match.combined.match_entropy_iccp` only: a fix whose largest 1-σ
        exceeds this times the 1-σ of a uniform prior over the searched region
        (:func:`~jaxgrav.match.integrity.region_sigma`) is rejected (status 512): the
        readings must narrow the search (default ``inf``: no test).
    max_p_worse : float
        :func:`~jaxgrav.match.combined.match_entropy_iccp` only: a fix is rejected (status
        131072) when the probability, under its Gaussian ``N(fix, covariance_m2)``, that
        the truth lies nearer the INS track than the fix exceeds this
        (:func:`~jaxgrav.match.combined.p_worse_than_ins`; at most 0.5; default ``inf``:
        no test).
    max_offset_m : float
        :func:`~jaxgrav.match.combined.match_entropy_iccp` only: a fix farther than
        this from the INS track (m, the mean offset) is rejected (status 65536);
        :func:`~jaxgrav.match.sizing.iccp_config_for` sets 1.5 × the drift radius for
        the fine stage (default ``inf``: no test).
    bias_sigma : float
        The combined matcher only: σ (map units) of a common reading bias, e.g. a
        gravimeter's offset or the Eötvös error of a velocity error; 0 (default):
        readings bias-free, ``inf``: a flat prior. With a bias, the GLS scores
        marginalise it and each ICCP start fits the readings minus the GLS bias at
        that start (ICCP itself has no bias term).
    """

    window_m: float = 3000.0
    max_step_m: float = 1000.0
    contour_tol: float = float("inf")
    tol_m: float = 1.0
    max_rotation_deg: float = 90.0
    noise: float = 0.0
    accept_chi2: float = 7.81
    max_iter: int = static_field(30)
    newton_steps: int = static_field(3)
    refine_steps: int = static_field(0)
    weights: str = static_field("uniform")
    method: str = static_field("bicubic")
    map_error_mgal: float = 0.0
    map_error_length_m: float = 10000.0
    bias_sigma: float = 0.0
    map_error_order: int = static_field(2)
    fix: str = static_field("coarse")
    resolved_n_effective: float = 3.0
    max_sigma_m: float = float("inf")
    max_second_mode: float = float("inf")
    max_chi2_per_dof: float = float("inf")
    max_edge_mass: float = float("inf")
    max_offset_m: float = float("inf")
    region: str = static_field("square")
    max_sigma_ratio: float = float("inf")
    max_p_worse: float = float("inf")

    def __post_init__(self):
        if isinstance(self.fix, str) and self.fix not in ("coarse", "posterior"):
            raise ValueError(f"fix must be 'coarse' or 'posterior'; got {self.fix!r}")
        if isinstance(self.region, str) and self.region not in ("square", "disc"):
            raise ValueError(f"region must be 'square' or 'disc'; got {self.region!r}")
        for name in ("max_sigma_ratio", "max_p_worse"):
            arr = concrete(getattr(self, name))
            if arr is not None and arr.dtype != object and not (
                    np.all(~np.isnan(arr)) and np.all(arr >= 0)):
                raise ValueError(f"{name} must be >= 0 (inf: no test); got {arr}")
        arr = concrete(self.bias_sigma)
        if arr is not None and arr.dtype != object and not (
                np.all(~np.isnan(arr)) and np.all(arr >= 0)):
            raise ValueError(f"bias_sigma must be >= 0 (inf: a flat prior); got {arr}")
        for name in ("map_error_mgal", "map_error_length_m"):
            arr = concrete(getattr(self, name))
            if arr is not None and arr.dtype != object and not (
                    np.all(np.isfinite(arr)) and np.all(arr >= 0)):
                raise ValueError(f"{name} must be finite and >= 0; got {arr}")
        if isinstance(self.max_iter, int) and self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1; got {self.max_iter!r}")
        if isinstance(self.newton_steps, int) and self.newton_steps < 1:
            raise ValueError(f"newton_steps must be >= 1; got {self.newton_steps!r}")
        if isinstance(self.refine_steps, int) and self.refine_steps < 0:
            raise ValueError(f"refine_steps must be >= 0; got {self.refine_steps!r}")
        if isinstance(self.method, str) and self.method != "bicubic":
            raise ValueError(f"method must be 'bicubic' (a smooth gradient); got {self.method!r}")
        if isinstance(self.weights, str) and self.weights not in WEIGHTS:
            raise ValueError(f"weights must be one of {WEIGHTS}; got {self.weights!r}")
