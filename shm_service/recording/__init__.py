"""Recordings of the data contract (``/work/shared/spec/recording-format.md``): MCAP files with
JSON messages, a ``rig.json`` attachment and optional ``truth`` metadata.

``RecordingWriter`` writes them; ``read_recording`` is the one reader for everything downstream
(it checks the contract, keeps what is valid and reports what is not); ``inspect_recording`` and
``format_inspection`` summarise a file for ``shm inspect``. Topics, schemas and payload layouts
are the contract package's (re-exported here for the readers' users).
"""

from contract import ESTIMATE_TOPIC, PAYLOAD_FIELDS, SCHEMAS, TRUTH_TOPIC, classify_topic

from ._follow import FollowBlock, RecordingFollower
from ._inspect import format_inspection, inspect_recording
from ._reader import Channel, ReadReport, Recording, RecordingError, TopicReport, read_recording
from ._writer import RecordingWriter, encode_payloads_json

__all__ = [
    "ESTIMATE_TOPIC",
    "PAYLOAD_FIELDS",
    "SCHEMAS",
    "TRUTH_TOPIC",
    "Channel",
    "FollowBlock",
    "ReadReport",
    "Recording",
    "RecordingError",
    "RecordingFollower",
    "RecordingWriter",
    "TopicReport",
    "classify_topic",
    "encode_payloads_json",
    "format_inspection",
    "inspect_recording",
    "read_recording",
]
