"""spotsim: multi-point contact simulation of the self-centring grasp of space modules.

    import spotsim
    scenario = spotsim.load_scenario("config/single_arm_case_I.yaml")
    result = spotsim.simulate(scenario)
    print(result.grasp["residual_offset_mm"])
    spotsim.write_results(result, "results/case_I")
    summary, timeseries = spotsim.read_results("results/case_I")
    spotsim.run_scenario(scenario, "results/case_I")  # as `spotsim run`: with its error estimate
"""

from .assemble.model import Model, build_model
from .errors import ModelError, ScenarioError, SimulationError, SpotsimError
from .results import read_results, run_scenario, write_results
from .run import Result, simulate
from .scenario import Scenario, from_dict, load_scenario, replace, to_yaml
from .studies.ensemble import EnsembleResult, ensemble
from .studies.sweep import sweep
from .version import __version__

__all__ = [
    "Model",
    "ModelError",
    "EnsembleResult",
    "Result",
    "Scenario",
    "ScenarioError",
    "SimulationError",
    "SpotsimError",
    "build_model",
    "ensemble",
    "from_dict",
    "load_scenario",
    "read_results",
    "replace",
    "run_scenario",
    "simulate",
    "sweep",
    "to_yaml",
    "write_results",
    "__version__",
]
