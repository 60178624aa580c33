"""Reports: the paper's tables and figures from the store (``compare-baselines``, ``report``).

- :mod:`~morfic_cli.report.paper`: the paper's published numbers, once, as data.
- :mod:`~morfic_cli.report.gather`: runs and their stored results, with provenance.
- :mod:`~morfic_cli.report.compare`: mean ± std over seeds (``morfic compare-baselines``).
- :mod:`~morfic_cli.report.model`, :mod:`~morfic_cli.report.tables`: the paper's tables, bold marks included.
- :mod:`~morfic_cli.report.latex`, :mod:`~morfic_cli.report.markdown`, :mod:`~morfic_cli.report.figures`: output.
- :mod:`~morfic_cli.report.support`: the morphology-support table artifact.
- :mod:`~morfic_cli.report.build`: the report artifact (``morfic report``).

The pipeline that produces the results (``morfic reproduce``) is :mod:`morfic_cli.pipeline`.

Importing this package imports nothing heavy; see docs/report.md.
"""
