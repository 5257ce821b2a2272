"""Recall tables with query conditions: the condition column and tables appear only when a
non-clean condition is in the rows; clean rows print as before."""

from markerplace.testbed.reporting.tables import (
    CSV_COLUMNS,
    conditions_table,
    main_tables_markdown,
    read_recall_csv,
    tables_markdown,
    write_recall_csv,
)


def _rows(conditions):
    return [dict(scene="tiny", method=m, run=0, k=k, test_set="weighted", condition=c, threshold="5cm/5deg",
                 recall=r, n_tests=10)
            for c, shift in zip(conditions, (0.0, -0.2, -0.3)) for m, k, r in (("none", 0, 0.5), ("omp", 2, 0.7))
            for r in [r + shift]]


def test_clean_rows_print_as_before(tmp_path):
    rows = _rows(["clean"])
    write_recall_csv(tmp_path / "r.csv", rows)
    assert (tmp_path / "r.csv").read_text().splitlines()[0] == ",".join(CSV_COLUMNS)
    legacy = [{k: v for k, v in r.items() if k != "condition"} for r in rows]  # rows made before conditions
    assert tables_markdown(rows, [2], "5cm/5deg", ["5cm/5deg"]) == tables_markdown(legacy, [2], "5cm/5deg", ["5cm/5deg"])
    assert "condition" not in main_tables_markdown(rows, [2], "5cm/5deg").lower()


def test_conditions_get_a_column_and_a_table(tmp_path):
    rows = _rows(["clean", "blur", "noise"])
    write_recall_csv(tmp_path / "r.csv", rows)
    back = read_recall_csv(tmp_path / "r.csv")
    assert [r["condition"] for r in back] == ["clean"] * 2 + ["blur"] * 2 + ["noise"] * 2
    md = tables_markdown(rows, [2], "5cm/5deg", ["5cm/5deg"])
    assert "## Test set `weighted`, condition `blur`, recall at 5cm/5deg" in md
    assert "| tiny | weighted | noise | Ours | 5cm/5deg | 20.0 | 40.0 |" in md
    table = conditions_table(rows, "5cm/5deg", [2])
    assert "| Scene | Test set | Method | k | `clean` | `blur` | `noise` |" in table
    assert "| tiny | weighted | No markers | 0 | 50.0 | 30.0 | 20.0 |" in table
    assert "| tiny | weighted | Ours | 2 | 70.0 | 50.0 | 40.0 |" in table
