"""Where to measure next: Bayesian experimental design from a posterior run
(``brdf-infer design``)."""

from brdf_infer.design._candidates import (
    Candidates,
    design_series,
    grid_candidates,
    reach_limit,
    reachable,
    read_candidates,
    session_scene,
)
from brdf_infer.design._estimate import ESS_FLOOR, candidate_outcomes, set_outcome
from brdf_infer.design._study import (
    DESIGN_FIGURE,
    DESIGN_FILE,
    DesignOptions,
    DesignResult,
    DesignRun,
    candidate_measurements,
    design,
    design_coating,
    load_design_run,
    predictive,
    target_values,
    write_design,
)
from brdf_infer.design._table import (
    DESIGN_HEADERS,
    current_words,
    design_rows,
    reach_line,
    target_scale,
)
from brdf_infer.scene.design_target import DesignTarget, parse_target

__all__ = [
    "DESIGN_FIGURE",
    "DESIGN_FILE",
    "DESIGN_HEADERS",
    "ESS_FLOOR",
    "Candidates",
    "DesignOptions",
    "DesignResult",
    "DesignRun",
    "DesignTarget",
    "candidate_measurements",
    "candidate_outcomes",
    "current_words",
    "design",
    "design_coating",
    "design_rows",
    "design_series",
    "grid_candidates",
    "load_design_run",
    "parse_target",
    "predictive",
    "reach_limit",
    "reach_line",
    "reachable",
    "read_candidates",
    "session_scene",
    "set_outcome",
    "target_scale",
    "target_values",
    "write_design",
]
