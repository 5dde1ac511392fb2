"""The twin's Python API: every public function and class of the analyses, in one place (docs/api.md).

Import from here rather than from the modules that define the names: the modules may move between layers, this
list stays. Every name is documented in docs/api.md (tests/test_api_docs.py fails on a name the page lacks, and
runs the page's examples)::

    from rimd_sim.api import load_config, sweep

    result = sweep(load_config(), [3.5, 3.75, 4.0], workers=1)

The module sits in its own layer of the import contracts (pyproject.toml): it imports the analyses, the model,
the settings and the errors, never ``rimd_sim.ros`` or ``rimd_sim.cli``, and nothing in the package below it imports
it. Importing it loads the analyses (NumPy, SciPy, the compiled model): ``import rimd_sim`` alone still imports
nothing, so ``rimd --help`` stays fast.
"""

from __future__ import annotations

from rimd_sim.analysis.dynamics.basins import BasinsResult, basins, default_basin_ranges
from rimd_sim.analysis.dynamics.bifurcation import BifurcationBranch, BifurcationPoint, bifurcation
from rimd_sim.analysis.dynamics.continuation import (
    Bifurcation,
    Branch,
    BranchPoint,
    ContinuationResult,
    ContinuationSettings,
    StartOutsideDomain,
    continuation,
    fixed_point,
    monodromy,
)
from rimd_sim.analysis.dynamics.lyapunov import CHAOS_THRESHOLD, LyapunovResult, is_chaotic, largest_lyapunov
from rimd_sim.analysis.dynamics.maps import ParameterMap, mappable_parameters, parameter_map
from rimd_sim.analysis.dynamics.peterka import START_NAMES, PeterkaResult, peterka
from rimd_sim.analysis.dynamics.steady import Orbit, steady_orbit
from rimd_sim.analysis.dynamics.sweep import SweepPoint, SweepResult, band_peak, sweep
from rimd_sim.analysis.executor import SchedulerError, TaskRunner, open_executor, run_tasks
from rimd_sim.analysis.identification.identify import Estimate, Identification, IdentificationError, identify
from rimd_sim.analysis.recordings.reading import Reading
from rimd_sim.analysis.recordings.reading import read as read_recording
from rimd_sim.analysis.recordings.recorded import Channel, RecordedData
from rimd_sim.analysis.recordings.recorded import load as load_recording
from rimd_sim.errors import (
    AnalysisError,
    CommandError,
    ConfigError,
    InputError,
    IntegrationError,
    RecordingError,
    RimdError,
    UnavailableError,
)
from rimd_sim.model.rig_model import ChatteringError, Impact, ModelOutput, RigModel, StroboPoint, model_for
from rimd_sim.settings.config import SimConfig, find_config_file, load_config

__all__ = [
    # configuration
    "SimConfig", "find_config_file", "load_config",
    # the model
    "ChatteringError", "Impact", "ModelOutput", "RigModel", "StroboPoint", "model_for",
    # sweep
    "SweepPoint", "SweepResult", "band_peak", "sweep",
    # bifurcation
    "BifurcationBranch", "BifurcationPoint", "bifurcation",
    # Poincare (steady orbit) and Lyapunov
    "CHAOS_THRESHOLD", "LyapunovResult", "Orbit", "is_chaotic", "largest_lyapunov", "steady_orbit",
    # Peterka and basins
    "START_NAMES", "BasinsResult", "PeterkaResult", "basins", "default_basin_ranges", "peterka",
    # continuation
    "Bifurcation", "Branch", "BranchPoint", "ContinuationResult", "ContinuationSettings", "StartOutsideDomain",
    "continuation", "fixed_point", "monodromy",
    # maps over the parameters
    "ParameterMap", "mappable_parameters", "parameter_map",
    # reading a recording
    "Channel", "Reading", "RecordedData", "load_recording", "read_recording",
    # identification
    "Estimate", "Identification", "IdentificationError", "identify",
    # the executor seam
    "SchedulerError", "TaskRunner", "open_executor", "run_tasks",
    # the error family
    "AnalysisError", "CommandError", "ConfigError", "InputError", "IntegrationError", "RecordingError", "RimdError",
    "UnavailableError",
]
