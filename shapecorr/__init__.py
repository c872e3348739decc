"""The application's stage functions, registered with the engine through the ``stages.plugins`` entry point
(``shapecorr = "shapecorr:PLUGIN"`` in pyproject.toml). Importing this package declares the plugin; the engine
imports its ``modules`` (which register the ``align.*``, ``corr.*`` and ``generate.*`` functions) when a pipeline
first names one of them, so commands on other plugins' pipelines do not import the scientific code."""
from stages.registry import Headline, Measure, Plugin

PLUGIN = Plugin(
    name="shapecorr",
    packages=("corr_core", "shapecorr"),
    modules=("shapecorr.alignment", "shapecorr.correspondence", "shapecorr.dense", "shapecorr.generators",
             "shapecorr.figures"),   # figures: mesh pictures of the correspondences, recovered azimuths
    namespaces=("align", "corr", "generate"),
    # the two libraries its functions import on first use, about half a second each (Open3D: the views and the
    # mesh pictures; pyplot: every figure), imported by each local worker while the client writes the datasets
    worker_warmup=("corr_core.open3d_loader:load_open3d", "corr_core.plotting.charts:pyplot"),
    report_packages=("scipy", "open3d", "scikit-image", "potpourri3d", "robust_laplacian", "matplotlib"),
    groups={"alignment": "Problem 1: alignment", "correspondence": "Problem 2: correspondence"},
    headlines=(
        Headline(
            group="alignment", title="Problem 1: joint alignment, per solver (stability: the run's solver)",
            rows=("spectral", "ppm", "lh"),
            measures=(Measure("exact vs truth", "ground_truth.exact_{row}"),
                      Measure("within one view", "ground_truth.within_one_view", only_row="solver"),
                      Measure("mean error (deg)", "ground_truth.mean_error_deg", better="min", only_row="solver"),
                      Measure("seed stability (min)", "seed_stability.min", only_row="solver"),
                      Measure("equivariance", "equivariance", only_row="solver"),
                      Measure("energy / upper bound", "solver_quality.energy_{row}",
                              divide_by="solver_quality.upper_bound")),
            figures=("align.contact_sheet:all_aligned.png", "align.azimuth_figure:azimuth_recovered_vs_true.png")),
        Headline(
            group="correspondence", title="Problem 2: landmark correspondence, per method",
            rows_from="accuracy",
            measures=(Measure("landmark accuracy", "accuracy.{row}"),
                      Measure("dense mean error", "dense.{row}.mean_error", better="min",
                              per_row={"mobius_all": "dense_map.mean_error"}),
                      Measure("dense within 0.25", "dense.{row}.within_0.25",
                              per_row={"mobius_all": "dense_map.within_0.25"}),
                      Measure("landmark transfer error", "landmark_error.{row}", better="min"),
                      Measure("seconds per pair", "@seconds_per_task", better="min")),
            row_inputs={"descriptor_sparse": "descriptor", "mrf_sparse": "mrf",
                        "mrf_oriented_sparse": "mrf_oriented", "mobius_sparse": "mobius_votes",
                        "mobius_all": "mobius_votes"},
            figures=("corr.landmark_figures:landmarks_worst_per_method.png",
                     "corr.evaluate:kim_curves.png", "corr.dense_figures:dense_dense_auto.png")),
    ),
    sweep_metrics=("ground_truth.exact", "ground_truth.mean_error_deg", "seed_stability.min", "equivariance",
                   "accuracy.descriptor", "accuracy.mrf", "accuracy.mrf_oriented", "accuracy.mobius_all", "dense_map.mean_error"),
)
