"""The report of an identification, in every form it takes.

One JSON document (:mod:`~vibid.report.document`, shared/spec/report-format.md) is the
source; every other form reads its values from it through one list of quantities
(:mod:`~vibid.report.values`), so none can disagree with it:

* :func:`build_report`, :func:`write_report`: the JSON report;
* :func:`summary_markdown`: ``report.md`` (:mod:`~vibid.report.markdown`);
* :func:`console_summary`, :func:`plausibility_lines`: the console's lines at the end of a
  job (:mod:`~vibid.report.console`);
* :func:`parameter_table`, :func:`artifact_key`: the Prefect UI's parameter table and
  artifact keys;
* :data:`FIGURES`: the figures, one list that the PNG files, report.md and the Prefect UI
  follow (:mod:`~vibid.report.figures`; the drawing itself: :mod:`~vibid.report.plots`);
* :func:`write_lab_report`: the report folder (report.md, report.json, the figures;
  :mod:`~vibid.report.folder`);
* :func:`summary_row`, :func:`summary_csv`, :func:`summary_table_markdown`: the summary of
  many sessions (:mod:`~vibid.report.batch`);
* the report's ``not_done``: each stage after the fit that failed, in one line, the rest of
  the report written (:mod:`~vibid.not_done`).

Importing it loads neither matplotlib nor JAX: the figures and the fine model import them
when drawn.
"""

from vibid.report.batch import summary_csv, summary_row, summary_table_markdown
from vibid.report.console import console_summary, plausibility_lines
from vibid.report.document import FORMAT, FORMAT_VERSION, build_report, write_report
from vibid.report.figures import FIGURES, ReportFigure, draw_figures
from vibid.report.folder import REPORT_JSON, REPORT_MD, artifact_key, write_lab_report
from vibid.report.markdown import summary_markdown
from vibid.report.values import Quantity, parameter_table, quantities

__all__ = [
    "FIGURES",
    "FORMAT",
    "FORMAT_VERSION",
    "REPORT_JSON",
    "REPORT_MD",
    "Quantity",
    "ReportFigure",
    "artifact_key",
    "build_report",
    "console_summary",
    "draw_figures",
    "parameter_table",
    "plausibility_lines",
    "quantities",
    "summary_csv",
    "summary_markdown",
    "summary_row",
    "summary_table_markdown",
    "write_lab_report",
    "write_report",
]
