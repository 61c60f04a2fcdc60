"""The run core stays narrow (issue 21): the figures of ``studies/architecture.py`` held at their goals, so that a
cross-cutting feature goes behind an interface instead of widening the core again (the last round's MPI, restart and
error control grew it to 3 import cycles, MPI in 8 modules, 9 switches on the model kind and 13 probes)."""
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def figures():
    spec = importlib.util.spec_from_file_location("architecture", ROOT / "studies" / "architecture.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.measure()


def test_no_import_cycles_and_no_imports_up_the_layers(figures):
    assert figures["import_cycles"] == [] and figures["back_arrows"] == [], (figures["import_cycles"],
                                                                              figures["back_arrows"])


def test_mpi_stays_in_two_modules_besides_parallel(figures):
    modules = sorted({s.split(":")[0] for s in figures["mpi_aware_modules"]})
    assert len(modules) <= 2, modules


def test_no_switches_on_the_model_kind_and_no_probes(figures):
    assert figures["kind_switches"] == [] and figures["probes"] == [], (figures["kind_switches"], figures["probes"])


def test_numerics_are_listed_once_and_adaptive_is_decided_once(figures):
    assert figures["numerics_name_lists"] == [], figures["numerics_name_lists"]
    assert len(figures["rtol_positive_tests"]) == 1, figures["rtol_positive_tests"]


def test_classes_and_functions_stay_small(figures):
    assert figures["classes_over_250"] == [] and figures["functions_over_60"] == [], (
        figures["classes_over_250"], figures["functions_over_60"])
