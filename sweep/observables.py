"""The observables of phase.nc: for each, the scalar of the run files it is made of and its
long name; the run scalars that are not observables."""

from __future__ import annotations

#: phase.nc variable -> (scalar in the run file, long_name). Units are all "1": the model is
#: dimensionless (lengths in units of the domain size L, times in units of tau).
OBSERVABLES: dict[str, tuple[str, str]] = {
    "sigma2_S": (
        "sigma2_S_final",
        "variance of the nematic order parameter S over the domain at t_final",
    ),
    "mean_S": ("mean_S_final", "domain mean of the nematic order parameter S at t_final"),
    "cos2theta": (
        "cos2theta_final",
        "domain mean of cos(2 theta) (director anisotropy) at t_final",
    ),
    "lambda": (
        "lambda_final",
        "pattern size lambda (radial spectrum peak) at t_final (units of L)",
    ),
    "lambda_peak": (
        "lambda_peak",
        "pattern size lambda at the first peak of sigma2_S(t), growth-peak rule (units of L)",
    ),
    "t_peak": ("t_peak", "time of the first peak of sigma2_S(t), growth-peak rule (units of tau)"),
    "lambda_peak_literal": (
        "lambda_peak_literal",
        "pattern size lambda at the first local "
        "maximum of sigma2_S(t), the paper's literal rule (units of L)",
    ),
    "t_peak_literal": (
        "t_peak_literal",
        "time of the first local maximum of sigma2_S(t), the paper's literal rule (units of tau)",
    ),
    "lambda_mean": ("lambda_mean_final", "pattern size 2 pi / mean |k| at t_final (units of L)"),
    "lambda_mean_peak": (
        "lambda_mean_peak",
        "pattern size 2 pi / mean |k| at the first peak "
        "of sigma2_S(t), growth-peak rule (units of L)",
    ),
    "rate_margin_min": (
        "rate_margin_min",
        "smallest well-posedness margin of the rate problem over the run (1 passive, 0 ill posed)",
    ),
}
#: Scalars of the run files that are not observables (they differ between identical runs).
NOT_OBSERVABLES = {"wall_time"}
