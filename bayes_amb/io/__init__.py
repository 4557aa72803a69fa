"""File I/O: atomic writes, the controller file and the recording format (CSV + JSON),
and bringing rig data in (DAQ files through a channel map, MATLAB controllers)."""

from bayes_amb.io.atomic import (
    atomic_path,
    json_text,
    parse_json_text,
    read_json,
    write_bytes_atomic,
    write_json_atomic,
    write_text_atomic,
)
from bayes_amb.io.channel_map import ChannelMap, channel_map_from_dict, load_channel_map
from bayes_amb.io.controller_file import (
    CONTROLLER_FORMAT,
    CONTROLLER_INPUTS,
    CONTROLLER_OUTPUTS,
    ControllerFile,
    check_fits_rig,
    controller_from_dict,
    load_controller,
)
from bayes_amb.io.controller_import import ControllerImport, import_controller
from bayes_amb.io.daq import SOURCE_FORMATS, read_channels
from bayes_amb.io.daq_export import export_daq, realistic_channel_map
from bayes_amb.io.daq_import import import_recording
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
    "SOURCE_FORMATS",
    "UNITS",
    "ChannelMap",
    "ControllerFile",
    "ControllerImport",
    "Recording",
    "atomic_path",
    "channel_map_from_dict",
    "check_fits_rig",
    "controller_from_dict",
    "export_daq",
    "import_controller",
    "import_recording",
    "json_text",
    "load_channel_map",
    "load_controller",
    "load_recording",
    "load_truth",
    "make_recording",
    "parse_json_text",
    "read_channels",
    "read_json",
    "realistic_channel_map",
    "recording_paths",
    "save_recording",
    "write_bytes_atomic",
    "write_json_atomic",
    "write_text_atomic",
]
