"""Libraries of other feature sets: the column count declares the features; shape problems are one line per file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shared.feature_sets import HERAKLES, MappingError, generic_names, mapping_for, require_mapping
from shared.library import FEATURE_NAMES, LibraryError, load_library, save_library, validate_block, write_csv_dir
from shared.synthetic_wide import WIDE_FEATURE_NAMES, generate_wide_library


@pytest.fixture(scope="module")
def wide():
    return generate_wide_library(n_classes=4, n_demos=5, seed=1)


def write_rows(path: Path, blocks: list[np.ndarray]) -> None:
    rows = [",".join([str(i)] + [repr(float(v)) for v in f]) for b in blocks for i, f in enumerate(b)]
    path.write_text("\n".join(rows) + "\n")


def test_mappings_are_found_by_feature_names() -> None:
    assert mapping_for(FEATURE_NAMES) is HERAKLES and mapping_for(WIDE_FEATURE_NAMES) is None
    assert mapping_for(generic_names(12)) is None  # same count, other features: no mapping
    assert require_mapping(FEATURE_NAMES, "x") is HERAKLES
    with pytest.raises(MappingError) as exc:
        require_mapping(generic_names(16), "the swept volumes", "library 'w'")
    msg = str(exc.value)
    assert "\n" not in msg and "the swept volumes needs a mapping" in msg and "16 features" in msg
    assert "known: herakles" in msg


def test_generated_wide_library(wide) -> None:
    assert wide.feature_names == WIDE_FEATURE_NAMES and wide.n_features == 16 and wide.mapping is None
    assert wide.counts() == [5] * 4 and all(d.features.shape == (100, 16) for d in wide.demos)
    base_12 = np.stack([d.features[:, :12] for d in wide.demos])
    from shared.synthetic import generate_library

    np.testing.assert_array_equal(base_12, np.stack([d.features for d in generate_library(4, 5, seed=1).demos]))
    extra = np.stack([d.features[:, 12:] for d in wide.demos])  # (N, T, 4)
    assert np.all(np.isfinite(extra)) and extra.std(axis=(0, 1)).min() > 0.01
    # the extra channels move with the reach: at the end they differ between classes
    labels = np.array([d.label for d in wide.demos])
    ends = extra[:, -1]
    spread_between = np.std([ends[labels == m].mean(axis=0) for m in range(4)], axis=0).max()
    assert spread_between > 0.05


def test_16_feature_csv_loads_with_generic_names(wide, tmp_path) -> None:
    write_csv_dir(wide, tmp_path / "w")
    first = (tmp_path / "w" / "compound_0.csv").read_text().splitlines()[0]
    assert first.count(",") == 16  # 17 columns
    lib = load_library(tmp_path / "w")
    assert lib.issues == [] and lib.counts() == [5] * 4
    assert lib.feature_names == generic_names(16) and lib.mapping is None
    np.testing.assert_allclose(lib.demos[7].features, wide.demos[7].features, rtol=1e-8, atol=1e-9)
    # the npz keeps the declared feature names
    save_library(wide, tmp_path / "w.npz")
    back = load_library(tmp_path / "w.npz")
    assert back.feature_names == WIDE_FEATURE_NAMES and back.counts() == [5] * 4


def test_generic_features_are_validated_by_the_general_rules() -> None:
    f = np.full((40, 16), 50.0)  # out of every herakles range: no ranges for unmapped features
    f[:, 0] = np.linspace(0, 1, 40)
    assert validate_block(f, generic_names(16)) == []
    f[3, 5] = np.nan
    f[:, 9] = 0.0
    reasons = validate_block(f, generic_names(16))
    assert any("non-finite values in feature_6 at samples 3" in r for r in reasons)
    assert any("dead channel(s): feature_10" in r for r in reasons)


def test_a_file_of_another_column_count_is_one_line(wide, tmp_path) -> None:
    from shared.synthetic import generate_library

    write_csv_dir(generate_library(4, 5, seed=2), tmp_path / "mixed")
    write_csv_dir(wide, tmp_path / "w")
    (tmp_path / "mixed" / "compound_2.csv").write_bytes((tmp_path / "w" / "compound_2.csv").read_bytes())
    lib = load_library(tmp_path / "mixed")
    assert lib.feature_names == FEATURE_NAMES and lib.counts() == [5, 5, 0, 5]
    assert len(lib.issues) == 1
    issue = lib.issues[0]
    assert (issue.class_name, issue.block) == ("compound_2", -1)
    assert "500 lines of 17 columns" in issue.reason and "13 columns" in issue.reason


def test_files_without_a_majority_count_are_one_error_line(wide, tmp_path) -> None:
    from shared.synthetic import generate_library

    write_csv_dir(generate_library(2, 3, seed=2), tmp_path / "tie")
    for m in (2, 3):
        write_rows(tmp_path / "tie" / f"compound_{m}.csv", [d.features for d in wide.by_class(m)])
    with pytest.raises(LibraryError) as exc:
        load_library(tmp_path / "tie")
    msg = str(exc.value)
    assert "\n" not in msg and "disagree on the column count" in msg
    assert "compound_0.csv: 300 lines of 13 columns" in msg and "compound_3.csv: 500 lines of 17 columns" in msg


def test_many_stray_lines_in_a_block_are_one_reason(tmp_path) -> None:
    rng = np.random.default_rng(0)
    blocks = [np.c_[np.full((40, 3), 0.9), rng.normal(0.0, 0.1, (40, 9))] for _ in range(3)]
    write_rows(tmp_path / "compound_0.csv", blocks)
    lines = (tmp_path / "compound_0.csv").read_text().splitlines()
    for i in range(45, 75):  # block 1: 30 lines gain two columns
        lines[i] += ",1.0,2.0"
    (tmp_path / "compound_0.csv").write_text("\n".join(lines) + "\n")
    lib = load_library(tmp_path)
    assert [i.block for i in lib.issues] == [1]
    reason = lib.issues[0].reason
    assert "30 lines (lines 46-75) have 15 columns, expected 13" in reason and reason.count("line") == 3
