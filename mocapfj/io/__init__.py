"""Files only: recording bundles, C3D, TRC, controller CSV, rig and board TOML, results JSON.

No maths here. Everything read is converted to SI units; see docs/formats.md.
"""

from .atomic import atomic_path, write_bytes_atomic, write_text_atomic
from .c3d import read_c3d, write_c3d
from .calib import read_board, read_rig, write_board, write_rig
from .clusters import read_clusters, write_clusters
from .csvio import read_csv_columns, write_csv_columns
from .recording import files_outside_bundle, load_recording, read_controller, read_markers, write_markers, write_recording
from .results import read_detections, read_json, to_jsonable, write_detections, write_json
from .tomlio import read_toml, write_toml
from .trc import read_trc, write_trc

__all__ = [
    "atomic_path", "write_bytes_atomic", "write_text_atomic",
    "read_c3d", "write_c3d", "read_trc", "write_trc",
    "read_board", "write_board", "read_rig", "write_rig", "read_clusters", "write_clusters",
    "read_csv_columns", "write_csv_columns",
    "load_recording", "files_outside_bundle", "write_recording", "read_controller", "read_markers", "write_markers",
    "read_detections", "write_detections", "read_json", "write_json", "to_jsonable",
    "read_toml", "write_toml",
]
