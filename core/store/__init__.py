"""Stored results: result folders written as a unit (:mod:`.folders`), their manifests
(:mod:`.manifest`) and the bounded reading of what is stored (:mod:`.read`).

The names below are the layer's face: ``from estim import store; store.read_table(...)``.
"""

from estim.store.folders import (
    FIGURE_FORMATS,
    ResultFolder,
    atomic_write_bytes,
    ensure_writable,
    sha256,
    write_csv,
    write_figure,
)
from estim.store.manifest import (
    git_commit,
    spec_hash,
    versions,
    write_manifest,
    write_tables_and_manifest,
)
from estim.store.read import (
    MAX_MANIFEST_BYTES,
    MAX_TABLE_BYTES,
    read_manifest,
    read_stored,
    read_table,
    stored_table_path,
    stored_tables,
)

__all__ = ["FIGURE_FORMATS", "MAX_MANIFEST_BYTES", "MAX_TABLE_BYTES", "ResultFolder",
           "atomic_write_bytes", "ensure_writable", "git_commit", "read_manifest", "read_stored",
           "read_table", "sha256", "spec_hash", "stored_table_path", "stored_tables", "versions",
           "write_csv", "write_figure", "write_manifest", "write_tables_and_manifest"]
