"""HTML report of an identification (and validation) that a commissioning engineer can trust at a
glance: a verdict on top, data quality, parameters with uncertainty, their correlation, residuals,
Fig. 5, Fig. 6 and the provenance of every number.

    assemble    :func:`make_report` (pre-flight, identify or its refusal, validate, verdict,
                provenance) -> :class:`Report`; :func:`report_of` for results computed elsewhere
    reference   what to compare with: ``--reference`` file, simulator truth, Table 2 for the
                paper's prototype only; :func:`parameter_table`
    plan        the excitation plan the logs were driven from (``--plan`` or found by a sidecar):
                :func:`read_plan`, :func:`excitation_plan`, the section's figure and HTML
    document    :func:`report_html`, :func:`write_report` (one self-contained HTML file)

Example::

    from agvdyn.identification import load_logs, platform_for
    from agvdyn.report import make_report, write_report

    logs = load_logs(["ident.parquet"])
    report = make_report(logs, platform_for(logs, None))
    report.verdict.outcome          # Outcome.IDENTIFIED, WARNINGS or REFUSED
    write_report("report.html", report)
"""
from agvdyn.report.assemble import (
    MAX_VALIDATION_NRMSE,
    InputFile,
    Outcome,
    Provenance,
    Report,
    Verdict,
    command_line,
    input_file,
    make_report,
    report_of,
    verdict_of,
)
from agvdyn.report.document import figure_png, report_html, write_report
from agvdyn.report.plan import ExcitationPlan, PlanFile, excitation_plan, read_plan
from agvdyn.report.reference import (
    TABLE2,
    Reference,
    choose_reference,
    parameter_table,
    reference_from_file,
    sidecar_truth,
)

__all__ = [
    "MAX_VALIDATION_NRMSE", "InputFile", "Outcome", "Provenance", "Report", "Verdict", "command_line", "input_file",
    "make_report", "report_of", "verdict_of", "figure_png", "report_html", "write_report", "TABLE2", "Reference",
    "choose_reference", "parameter_table", "reference_from_file", "sidecar_truth", "ExcitationPlan", "PlanFile",
    "excitation_plan", "read_plan",
]
