"""Stored results: result folders written as a unit (:mod:`.folders`), the tables, figures,
manifest and run record written into them (:mod:`.writing`) and the bounded reading of what
is stored (:mod:`.read`), one experiment's folder read one way by every command
(:mod:`.stored`).

The names below are the layer's face: ``from estim import store; store.read_table(...)``.
"""

from estim.store.folders import (
    ResultFolder,
    atomic_write_bytes,
    ensure_free,
    ensure_writable,
    output_file,
    sha256,
)
from estim.store.read import (
    MAX_MANIFEST_BYTES,
    MAX_TABLE_BYTES,
    read_manifest,
    read_run_record,
    read_stored,
    read_table,
    stored_table_path,
)
from estim.store.stored import (
    MAX_FIGURE_BYTES,
    Stored,
    manifest_problems,
    open_stored,
    stored_folders,
    stored_tables,
)
from estim.store.writing import (
    FIGURE_FORMATS,
    MACHINE_DIR,
    RUN_RECORD,
    figure_path,
    git_commit,
    spec_hash,
    table_path,
    versions,
    write_csv,
    write_figure,
    write_manifest,
    write_tables_and_manifest,
)

__all__ = ["FIGURE_FORMATS", "MACHINE_DIR", "MAX_FIGURE_BYTES", "MAX_MANIFEST_BYTES",
           "MAX_TABLE_BYTES", "RUN_RECORD", "ResultFolder", "Stored", "atomic_write_bytes",
           "ensure_free", "ensure_writable", "figure_path", "git_commit", "manifest_problems",
           "open_stored", "output_file", "read_manifest", "read_run_record", "read_stored",
           "read_table", "sha256", "spec_hash", "stored_folders", "stored_table_path",
           "stored_tables", "table_path", "versions", "write_csv", "write_figure",
           "write_manifest", "write_tables_and_manifest"]
