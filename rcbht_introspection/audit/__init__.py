"""A data set's quality before training (`rcbht audit`, docs/audit.md): sub-task durations and
their outliers, changes of the labelling convention, sessions of the free-motion wrench level,
and the sensor's frozen stretches, dropped stamps, rate and gaps. Pure NumPy and SciPy; the
figure is plots/audit.py's."""

from rcbht_introspection.audit.report import (
    AuditReport,
    audit_facts,
    audit_paths,
    audit_trials,
    report_dict,
    report_text,
)
from rcbht_introspection.audit.settings import AuditSettings

__all__ = [
    "AuditReport",
    "AuditSettings",
    "audit_facts",
    "audit_paths",
    "audit_trials",
    "report_dict",
    "report_text",
]
