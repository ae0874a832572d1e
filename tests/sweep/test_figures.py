"""Every registered figure renders from a small REAL results folder (model at 32^2, short
t_final, run through the campaign manager's Python API: expand -> execute_run -> write_phase),
`nematic figures` writes fits.nc and the figures, and regenerate() is the run hook."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.sweep.analysis.fits_file import FITS, fit_notes
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.cli.products import regenerate_figures
from nematic_solids.sweep.errors import FigureError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.figures.produce import draw, plan, produce, regenerate
from nematic_solids.sweep.figures.registry import option_problems
from nematic_solids.sweep.outputs.aggregate import write_phase
from nematic_solids.sweep.run.task import RunTask, execute_run
from nematic_solids.sweep.spec import load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

#: alpha - B x K (figs. 2, 3). The runs are short (t/tau = 3): the fits may be poor or NaN,
#: the figures must still render. Fit options from the YAML (fewer bootstrap replicates).
SIZES = """\
name: sizes
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2, save_every: 0.5, snapshot_times: [1.5]}
sweep:
  axes:
    K: [2.0e-4, 1.0e-3]
    alpha_minus_B: [0.3, 1.0]
seeds: 2
fits: [{scaling: {n_boot: 100}}, {transition: {n_boot: 100, min_jump: 0.01}}]
figures: [fig2, fig3]
"""
#: chi x K x eps at alpha - B = 1 (fig. 4), one seed; snapshot fields without u.
PHASE = """\
name: phase
parameters: {alpha_minus_B: 1.0, noise_modes: 8}
numerics: {resolution: 32, t_final: 2, save_every: 0.5}
sweep:
  axes:
    chi: [0.0, 5.0]
    K: [1.0e-4, 1.0e-2]
    eps: [0.0, 0.05]
seeds: 1
store: {snapshot_fields: [q1, q2, I1bar], snapshot_dtype: float32}
fits: [{anisotropy: {n_boot: 100}}]
"""
#: chi x eps, linear incompressible mechanics, S0 = 0 with noise (fig. A1). No I1bar stored.
STABILITY = """\
name: stab
parameters: {S0: 0.0, A0: 1.0, K: 1.0e-4, alpha_minus_B: 1.0, noise_amplitude: 1.0e-3,
             noise_modes: 8, zeta: 1.0}  # zeta as campaigns/figA1.yaml
numerics: {mechanics: linear, incompressible: true, resolution: 32, t_final: 8, save_every: 1,
           tolerance: 1.0e-4}
sweep:
  axes:
    chi: [3.0, 10.0]
    eps: [0.05, 0.2]
seeds: 2
store: {snapshot_fields: [q1, q2]}
figures: [figA1]
"""


def build(folder: Path, text: str) -> SimpleNamespace:
    """Run a campaign for real, in this process, and aggregate it."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "campaign.yaml"
    path.write_text(text)
    campaign = load_campaign(path)
    store = CampaignStore(folder / "results", campaign.name)
    store.ensure()
    expansion = expand(campaign)
    for run in expansion:
        execute_run(RunTask.from_spec(run, store, campaign.name, campaign.store))
    write_phase(expansion, store)
    return SimpleNamespace(
        path=path, campaign=campaign, results=folder / "results", root=store.root
    )


@pytest.fixture(scope="module")
def sizes(tmp_path_factory):
    return build(tmp_path_factory.mktemp("sizes"), SIZES)


@pytest.fixture(scope="module")
def phase4(tmp_path_factory):
    return build(tmp_path_factory.mktemp("phase"), PHASE)


@pytest.fixture(scope="module")
def stab(tmp_path_factory):
    return build(tmp_path_factory.mktemp("stab"), STABILITY)


def assert_figure(paths: list[Path], name: str, root: Path) -> None:
    assert sorted(p.name for p in paths) == [f"{name}.pdf", f"{name}.png"]
    for p in paths:
        assert p.parent == root / "figures"
        assert p.stat().st_size > 10_000
    assert (root / "figures" / f"{name}.png").read_bytes()[:8] == PNG_MAGIC
    assert (root / "figures" / f"{name}.pdf").read_bytes()[:5] == b"%PDF-"
    assert not list((root / "figures").glob(".*"))  # no temporary file left


def test_registry_names_match_the_campaign_schema():
    from nematic_solids.sweep.spec.sections import registry

    assert sorted(registry("figures")) == [
        "fig2",
        "fig3",
        "fig3_growth",
        "fig4",
        "figA1",
        "loop",
        "moduli",
        "sh_phase",
        "switch",
    ]
    assert set(registry("fits")) >= {"transition", "alpha_cr", "scaling", "anisotropy", "stability"}


def test_fig2_and_fig3_render_and_fits_are_written(sizes):
    out = produce(sizes.campaign, sizes.results)
    assert out.failures == {}
    names = sorted({p.stem for p in out.paths})
    assert names == ["fig2", "fig3"]
    for n in names:
        assert_figure([p for p in out.paths if p.stem == n], n, sizes.root)
    with xr.open_dataset(sizes.root / FITS) as f:
        assert f["transition_location"].dims == ("K",)
        assert f["transition_location"].attrs["fit_min_jump"] == 0.01  # the campaign's options
        assert f["alpha_cr"].dims == ("K",)
        assert f["scaling_exponent"].attrs["fit_n_boot"] == 100
        assert f.attrs["campaign"] == "sizes"


def test_fig2_options_pick_the_snapshot_and_the_other_dims(sizes):
    paths = draw(
        "fig2",
        sizes.root,
        {
            "select": {"K": 1e-3},
            "seed": 1,
            "curves": 2,
            "snapshot": {"alpha_minus_B": 1.0, "seed": 1, "time": 1.5},
            "yscale": "log",
        },
    )
    assert_figure(paths, "fig2", sizes.root)
    with pytest.raises(FigureError, match="unknown option 'snapshots'"):
        draw("fig2", sizes.root, {"snapshots": []})


def test_fig3_growth_draws_lambda_and_sigma2_of_one_seed_with_its_peak(sizes):
    paths = draw("fig3_growth", sizes.root, {"select": {"K": 1e-3}, "seed": 1, "curves": 2})
    assert_figure(paths, "fig3_growth", sizes.root)
    with pytest.raises(FigureError, match="unknown option 'snapshot'"):
        draw("fig3_growth", sizes.root, {"snapshot": {}})


def test_fig4_renders_in_3d_with_the_caption_snapshots(phase4):
    out = produce(phase4.campaign, phase4.results)  # no figures listed: auto
    assert out.failures == {}
    assert_figure(out.paths, "fig4", phase4.root)
    with xr.open_dataset(phase4.root / FITS) as f:
        assert f["anisotropy_slope"].dims == ("chi", "K")


def test_fig4_snapshots_name_their_runs_grid(phase4, monkeypatch):
    """Each snapshot's title carries its run's grid (with ``resolution: auto`` the points of
    one figure have different grids)."""
    import matplotlib.figure

    titles: list[str] = []
    save = matplotlib.figure.Figure.savefig

    def record(self, *args, **kwargs):
        titles.extend(ax.get_title() for ax in self.axes)
        return save(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", record)
    draw("fig4", phase4.root, {})
    snapshots = [t for t in titles if t.startswith("(")]
    assert len(set(snapshots)) == 4  # (the figure is saved as png and pdf)
    assert all(t.endswith(", 32$^2$") for t in snapshots), snapshots


def test_fig4_in_2d_when_one_axis_is_fixed(phase4):
    paths = draw("fig4", phase4.root, {"select": {"K": 1e-4}})
    assert_figure(paths, "fig4", phase4.root)


def test_fig4_of_a_refined_union_grid_shows_the_points_run(phase4, tmp_path):
    """A refined campaign's phase.nc (each refined axis the union of the values run,
    seed_count 0 where a point was not run): panel (a) holds only the points run, panel (c)
    and the anisotropy fit skip the lines with one strain."""
    from nematic_solids.sweep.analysis.anisotropy import anisotropy
    from nematic_solids.sweep.figures.common import Results
    from nematic_solids.sweep.figures.fig4 import fig4

    root = tmp_path / "refined"
    shutil.copytree(phase4.root, root)
    phase = xr.load_dataset(root / "phase.nc")
    fill = {
        name: 0 if var.dtype.kind in "iu" else "" if var.dtype.kind in "OUS" else np.nan
        for name, var in phase.data_vars.items()
    }
    union = phase.reindex(chi=[0.0, 2.5, 5.0], fill_value=fill)
    at = {"K": 1.0e-4, "eps": 0.0}
    for name, var in phase.data_vars.items():  # chi = 2.5 run at one (K, eps) only
        if "chi" in var.dims:
            union[name].loc[{"chi": 2.5, **{k: v for k, v in at.items() if k in var.dims}}] = (
                var.sel(chi=0.0).sel({k: v for k, v in at.items() if k in var.dims})
            )
    union["seed_count"] = (union["status"] != 0).sum("seed")
    assert int(union["seed_count"].sum()) == 9
    union.to_netcdf(root / "phase.nc")

    figure = fig4(Results(root), {"select": {"K": 1e-4}})
    assert np.asarray(figure.axes[0].collections[0].get_offsets()).shape[0] == 5  # of 6
    figure.clear()
    fit = anisotropy(union, {"n_boot": 20})
    slope = fit["anisotropy_slope"].sel(chi=2.5).values
    assert np.isnan(slope).all()
    assert np.isfinite(fit["anisotropy_slope"].sel(chi=[0.0, 5.0]).values).all()
    assert_figure(draw("fig4", root, {}), "fig4", root)


def test_fig4_forced_on_an_alpha_minus_b_by_k_grid(sizes):
    """The caption's snapshots name chi; on a grid of alpha - B and K the unnamed axis is
    taken at its first value (this raised a TypeError before)."""
    paths = draw("fig4", sizes.root, {})
    assert_figure(paths, "fig4", sizes.root)


def test_figA1_renders_with_the_theory_line(stab):
    paths = regenerate(stab.campaign, stab.results)
    assert_figure(paths, "figA1", stab.root)
    with xr.open_dataset(stab.root / FITS) as f:
        unstable = f["stability_unstable"].values
        theory = f["stability_eps_c_theory"].sel(chi=10.0).item()
        # docs/stability.md section 7: eps_c = 0.10715 at chi (alpha - B) = 10
        assert theory == pytest.approx(0.10715, rel=1e-4)
        assert np.isinf(f["stability_eps_c_theory"].sel(chi=3.0).item()) or np.isnan(
            f["stability_eps_c_theory"].sel(chi=3.0).item()
        )
        assert set(np.unique(unstable)) <= {-1, 0, 1}
        assert f["stability_fraction_unstable"].dims == ("chi", "eps")


def test_cli_figures(sizes, tmp_path):
    runner = CliRunner()
    result = runner.invoke(
        app, ["figures", str(sizes.path), "--results", str(sizes.results), "--only", "fig3"]
    )
    assert result.exit_code == 0, result.output
    assert "fig3.png" in result.output
    assert "fits.nc" in result.output
    result = runner.invoke(
        app, ["figures", str(sizes.path), "--results", str(sizes.results), "--only", "fig9"]
    )
    assert result.exit_code == 2
    assert "unknown figure" in result.output
    empty = runner.invoke(app, ["figures", str(sizes.path), "--results", str(tmp_path)])
    assert empty.exit_code == 2
    assert "no phase diagram" in empty.output
    assert regenerate(sizes.campaign, tmp_path) == []


def test_plan_figures_listed_empty_or_default(sizes):
    """figures: [] plans no figure (the campaign's fits are still planned), no figures key
    plans every figure that applies to the grid, --only wins over both."""
    phase = xr.open_dataset(sizes.root / "phase.nc").load()
    base = SIZES.replace("figures: [fig2, fig3]\n", "")
    fits_, figs = plan(parse_campaign(base + "figures: []\n"), phase)
    assert figs == []
    assert [name for name, _ in fits_] == ["scaling", "transition"]
    fits_line = next(line for line in base.splitlines() if line.startswith("fits:"))
    no_fits = base.replace(fits_line, "fits: []")
    assert plan(parse_campaign(no_fits + "figures: []\n"), phase) == ([], [])
    _, figs = plan(parse_campaign(base), phase)
    assert [name for name, _ in figs] == ["fig2", "fig3", "fig3_growth"]  # what applies
    _, figs = plan(parse_campaign(base + "figures: []\n"), phase, names=["fig3"])
    assert figs == [("fig3", {})]


def test_empty_figures_list_draws_nothing_after_a_run(sizes, tmp_path):
    """The hook of `nematic run` (nematic_solids.sweep.cli.products.regenerate_figures) with
    figures: [] writes the campaign's fits and no figure; `nematic figures` says so, and --only
    still draws."""
    path = tmp_path / "campaign.yaml"
    path.write_text(SIZES.replace("figures: [fig2, fig3]", "figures: []"))
    campaign = load_campaign(path)
    assert campaign.figures == ()
    results = tmp_path / "results"
    root = results / campaign.name
    root.mkdir(parents=True)
    shutil.copy(sizes.root / "phase.nc", root / "phase.nc")
    out = regenerate_figures(campaign, results)
    assert out.paths == []
    assert out.failures == {}
    assert not (root / "figures").exists()
    with xr.open_dataset(root / FITS) as f:
        assert "scaling_exponent" in f
        assert "transition_location" in f
    runner = CliRunner()
    result = runner.invoke(app, ["figures", str(path), "--results", str(results)])
    assert result.exit_code == 0, result.output
    assert "no figures: the campaign lists none (figures: [])" in " ".join(result.output.split())
    assert not (root / "figures").exists()
    result = runner.invoke(app, ["figures", str(path), "--results", str(results), "--only", "fig3"])
    assert result.exit_code == 0, result.output
    assert (root / "figures" / "fig3.png").is_file()


def test_cli_figures_prints_the_fit_notes(sizes):
    """Runs left out of the size fits (first peak of sigma2_S at t_final in these short
    runs) and alpha_cr at its bound are reported under the fits.nc line."""
    result = CliRunner().invoke(
        app, ["figures", str(sizes.path), "--results", str(sizes.results), "--only", "fig3"]
    )
    assert result.exit_code == 0, result.output
    out = " ".join(result.output.split())
    with xr.open_dataset(sizes.root / FITS) as f:
        n = f["alpha_cr"].attrs["fit_n_unpeaked"]
        notes = fit_notes(f)
    assert n > 0  # t_final = 2: the patterns are still growing (growth rate > 10 % of its max)
    assert f"note: alpha_cr/scaling: {n} of" in out
    assert len(notes) >= 1
    for note in notes:
        assert " ".join(note.split()) in out


def test_a_figure_that_cannot_be_drawn_is_reported_not_fatal(stab):
    """fig2 needs alpha - B swept; this grid sweeps chi and eps: exit 4 with the reason in one
    line, figA1 still drawn (from the fits.nc on disk: --no-fits)."""
    produce(stab.campaign, stab.results, names=["figA1"])  # fits.nc present
    result = CliRunner().invoke(
        app,
        [
            "figures",
            str(stab.path),
            "--results",
            str(stab.results),
            "--only",
            "fig2",
            "--only",
            "figA1",
            "--no-fits",
        ],
    )
    assert result.exit_code == 4, result.output
    assert "failed: figure fig2: fig2 needs alpha_minus_B" in result.output
    out = " ".join(result.output.split())
    assert "figA1.png" in out


def test_option_problems_for_campaign_validation():
    assert option_problems("fig2", {"seed": 3, "yscale": "log"}) == []
    assert option_problems("fig3", {"seed": 3}) == ["unknown option 'seed'; allowed: none"]
    problems = option_problems("fig4", {"snapshots": [{"K": 1e-6}, 3]})
    assert len(problems) == 1
    assert "snapshots" in problems[0]
    assert option_problems("fig2", {"yscale": "symlog"}) == [
        "yscale = 'symlog'; expected 'linear' or 'log'"
    ]
