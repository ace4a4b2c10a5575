"""The paper's sensor-configuration study (Sections 4–5) on simulated recordings, and a design
mode that answers with the cheapest configuration meeting accuracy targets."""

from ._config import Configuration, StudySettings
from ._command import orderings, run_command
from ._design import DesignTargets, cheapest
from ._figures import make_design_figure, make_study_figures
from ._study import ConfigurationResult, StudyError, StudyResult, load_results, run_study, series_of

__all__ = [
    "Configuration",
    "ConfigurationResult",
    "DesignTargets",
    "StudyError",
    "StudyResult",
    "StudySettings",
    "cheapest",
    "load_results",
    "make_design_figure",
    "make_study_figures",
    "orderings",
    "run_command",
    "run_study",
    "series_of",
]
