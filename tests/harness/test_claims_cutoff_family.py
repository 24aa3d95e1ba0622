"""The Fig. 11 claims (``claims.real_rows``) find cmr-cutoff's two surfaces by the table's
``surface_family`` column, which the scene's recipe fills, never by an instance's name."""

from __future__ import annotations

import pandas as pd

from contactbench.harness.report.claims import real_rows
from contactbench.harness.run.rows import instance_columns
from contactbench.problems.scenes import get_scene
from contactbench.problems.scenes.cmr import POWER_LAW_FAMILY, ROLLOFF_FAMILY
from tests.harness.test_report_cmr import fabricate_cmr


def cutoff_table(family: str, instance_prefix: str) -> pd.DataFrame:
    """fabricate_cmr's rows as cmr-cutoff rows of ``family`` whose instances are named
    ``instance_prefix``-..., one step each."""
    table, _ = fabricate_cmr(family=family, scene="cmr-cutoff")
    table = table[table["step"] == 0].copy()
    table["instance"] = instance_prefix + "-" + table["instance"].astype(str)
    return table


def claim_ids(table: pd.DataFrame) -> set[str]:
    return {r.claim for r in real_rows(table, "fft")}


def test_each_surface_is_read_from_its_family_column_whatever_its_name() -> None:
    both = pd.concat([cutoff_table(ROLLOFF_FAMILY, "scan-a"), cutoff_table(POWER_LAW_FAMILY, "scan-b")])
    assert claim_ids(both) == {"real-cutoff-error", "real-cutoff-saving", "real-power-law-error",
                               "real-power-law-saving"}


def test_a_name_that_starts_with_the_other_kind_does_not_move_a_row() -> None:
    only_power_law = cutoff_table(POWER_LAW_FAMILY, ROLLOFF_FAMILY)
    assert claim_ids(only_power_law) == {"real-power-law-error", "real-power-law-saving"}


def test_the_scene_records_each_surface_s_family_in_the_table() -> None:
    scene = get_scene("cmr-cutoff")
    specs = scene.instances(scene.config(None))
    assert {instance_columns(s.params)["surface_family"] for s in specs} == {ROLLOFF_FAMILY, POWER_LAW_FAMILY}


def test_a_table_written_before_the_family_was_recorded_reads_it_from_the_scene_s_recipe() -> None:
    old = cutoff_table(POWER_LAW_FAMILY, "x")
    old["surface_family"] = ""
    old["N"], old["hurst"], old["seed"] = 256, 0.6, 0
    named = old.assign(instance="power-law-H0.6-N256-s0")  # the scene's own name of that recipe
    assert claim_ids(named) == {"real-power-law-error", "real-power-law-saving"}
    assert claim_ids(old) == set()  # a name the scene gives no recipe is read as no surface


def test_a_row_no_recipe_could_have_written_reads_as_no_surface() -> None:
    from contactbench.harness.report.sections.cmr import recipe_family

    assert recipe_family("rolloff-H0.6-N256-s0", 0, 0.6, -1) == ""  # (N and seed unknown: 0, -1)
