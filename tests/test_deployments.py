"""deployments/prefect.yaml points at real flows with valid schedules."""
import importlib
from pathlib import Path

import yaml
from cronsim import CronSim
from datetime import datetime

DOC = yaml.safe_load((Path(__file__).parents[1] / "deployments" / "prefect.yaml").read_text())


def test_every_entrypoint_is_a_prefect_flow_and_parameters_match_its_signature():
    import inspect

    from prefect.flows import Flow

    names = set()
    for dep in DOC["deployments"]:
        path, func = dep["entrypoint"].split(":")
        module = importlib.import_module(path.removesuffix(".py").replace("/", "."))
        flow = getattr(module, func)
        assert isinstance(flow, Flow)
        params = set(inspect.signature(flow.fn).parameters)
        assert set(dep["parameters"]) <= params, (dep["name"], set(dep["parameters"]) - params)
        names.add(dep["name"])
    assert {"reprocess-inbox", "campaign"} <= names


def test_schedules_are_valid_cron():
    crons = [s["cron"] for d in DOC["deployments"] for s in d.get("schedules", [])]
    assert crons
    for expr in crons:
        next(CronSim(expr, datetime(2026, 1, 1)))
