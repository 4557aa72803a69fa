"""File I/O: atomic writes, the controller file and the recording format (CSV + JSON)."""

from bayes_amb.io.atomic import (
    atomic_path,
    json_text,
    parse_json_text,
    read_json,
    write_bytes_atomic,
    write_json_atomic,
    write_text_atomic,
)
from bayes_amb.io.controller_file import (
    CONTROLLER_FORMAT,
    CONTROLLER_INPUTS,
    CONTROLLER_OUTPUTS,
    ControllerFile,
    check_fits_rig,
    controller_from_dict,
    load_controller,
)
from bayes_amb.io.recording import (
    EXCITATION_GROUPS,
    INJECTED_AT,
    RECORDING_FORMAT,
    UNITS,
    Recording,
    load_recording,
    load_truth,
    make_recording,
    recording_paths,
    save_recording,
)

__all__ = [
    "CONTROLLER_FORMAT",
    "CONTROLLER_INPUTS",
    "CONTROLLER_OUTPUTS",
    "EXCITATION_GROUPS",
    "INJECTED_AT",
    "RECORDING_FORMAT",
    "UNITS",
    "ControllerFile",
    "Recording",
    "atomic_path",
    "check_fits_rig",
    "controller_from_dict",
    "json_text",
    "load_controller",
    "load_recording",
    "load_truth",
    "make_recording",
    "parse_json_text",
    "read_json",
    "recording_paths",
    "save_recording",
    "write_bytes_atomic",
    "write_json_atomic",
    "write_text_atomic",
]
