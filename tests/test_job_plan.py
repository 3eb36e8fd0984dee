"""The job's plan decides once: the estimator is resolved once per merge, its weight
tables built once, and every front end (the header, the Blender node's baked tables)
reads the plan rather than the options."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.job.options import MergeOptions
from hdrio.job.plan import plan_merge
from hdrio.job.run import merge_stack
from hdrio.merge.methods import MERGE_METHODS
from hdrio.radiometry.estimators import ESTIMATORS, Estimator
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import demo_scene, gamma_inverse_response, render_brackets

TIMES = (1 / 64, 1 / 8, 1.0, 8.0)


@pytest.fixture(scope="module")
def stack() -> ExposureStack:
    scene = demo_scene(48, 64)
    moved = scene.copy()
    moved[10:20, 10:30] *= 6.0  # a mover in the last bracket: deghosting re-merges there
    codes = np.concatenate([render_brackets(scene, list(TIMES[:3])),
                            render_brackets(moved, list(TIMES[3:]))])
    return ExposureStack.from_arrays(codes, list(TIMES))


@pytest.fixture
def counted(monkeypatch):
    """Counts of the estimator's resolutions by name and of weight-table builds."""
    counts = {"canonical": 0, "weight_tables": 0}
    for registry in (ESTIMATORS, MERGE_METHODS):
        original = registry.canonical

        def canonical(name, original=original):
            counts["canonical"] += 1
            return original(name)

        monkeypatch.setattr(registry, "canonical", canonical)
    original_tables = Estimator.weight_tables

    def weight_tables(self, *args, **kwargs):
        counts["weight_tables"] += 1
        return original_tables(self, *args, **kwargs)

    monkeypatch.setattr(Estimator, "weight_tables", weight_tables)
    return counts


@pytest.mark.parametrize("options", [
    MergeOptions(),
    MergeOptions(merge="Poisson", uncertainty=True, align="off"),
    MergeOptions(merge="log", exclude_colour=(0, 0, 255), highlights="reconstruct"),
], ids=["default", "poisson-uncertainty", "log-excluded-highlights"])
def test_estimator_resolved_once_and_weights_built_once(stack, counted, options):
    # The stages (merge, the masked re-merges, highlights, uncertainty) and the header
    # all read the one plan: one look-up of --merge's name, one build of its tables.
    result = merge_stack(stack, options)
    assert counted == {"canonical": 1, "weight_tables": 1}
    assert result.plan.estimator is ESTIMATORS[options.merge]


def test_plan_resolves_the_options():
    plan = plan_merge(MergeOptions(merge="noise-optimal", uncertainty=False,
                                   no_skip=("warp",)))
    assert plan.estimator.name == "inverse-variance"
    assert plan.estimator.domain == "linear" and plan.fits_noise
    assert "warp" not in plan.skips and "covered" in plan.skips
    assert not plan_merge(MergeOptions(merge="tutorial")).fits_noise
    assert plan_merge(MergeOptions(merge="tutorial", uncertainty=True)).fits_noise
    assert plan_merge(MergeOptions(merge="Debevec1997")).estimator.domain == "log"


@pytest.mark.parametrize("field, value, words", [
    ("align", "sideways", "--align"), ("deghost", "maybe", "--deghost"),
    ("highlights", "paint", "highlights"), ("merge", "median", "unknown merge method"),
])
def test_plan_refuses_an_unknown_mode_naming_the_option(field, value, words):
    with pytest.raises((ValueError, KeyError), match=words):
        plan_merge(MergeOptions(**{field: value}))


def test_baked_merge_reads_the_plan():
    # The Blender node bakes the plan's weight tables: the same numbers the merge uses.
    from plugins.blender.baking import bake_merge

    response = gamma_inverse_response()[0]
    for merge in ("log", "linear"):
        options = MergeOptions(merge=merge)
        baked = bake_merge(response, TIMES, options)
        tables = plan_merge(options).weight_tables(response, np.asarray(TIMES), None)
        np.testing.assert_allclose(baked.weights.values()[0], tables[0].T, rtol=0,
                                   atol=1e-12 * tables.max())
        assert baked.log_domain == (merge == "log")
