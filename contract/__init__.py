"""What the layers agree on, defined once: the rig description (``rig.json``), topics and payload
layouts of the recording contract, the estimator's state layout, the mode map and the typed
documents exchanged by the pipeline, storage, HTTP API, dashboard and notifiers.

Bottom layer: imports no other package of the project (numpy and pydantic only), and every
other package imports its layouts and documents from here instead of re-deriving them.
"""

from ._network import is_loopback
from ._documents import (
    CURVATURE_CHART,
    FATIGUE_CONDITIONS,
    FatigueDocument,
    HotSpotLoadsDocument,
    LoadsWindowDocument,
    StationLoadsDocument,
    SENSOR_STATES,
    AidingChannelDocument,
    AlarmCountsDocument,
    AlarmDocument,
    AlarmEvent,
    AlarmEventDocument,
    AlarmLevel,
    AlarmsDocument,
    ArchiveStatusDocument,
    BaselineModeDocument,
    BaselineRequestDocument,
    BaselineStatusDocument,
    ChartDocument,
    ChartKind,
    ChartLevelsDocument,
    CurvatureDocument,
    DegradedImuDocument,
    ErrorDocument,
    EstimateDocument,
    EstimatorStatusDocument,
    FlagDocument,
    HealthDocument,
    IngestErrorDocument,
    IngestResultDocument,
    LastEstimateDocument,
    LiveEstimatesDocument,
    Level,
    LocationDocument,
    ModeDocument,
    ModelDocument,
    NotificationStatusDocument,
    PipelineStatusDocument,
    RestCalibrationDocument,
    SensorState,
    ServiceStatusDocument,
    SinkStatusDocument,
    SourceStatusDocument,
    SpectrumDocument,
    StatusDocument,
    StorageStatusDocument,
    StructureState,
    StructureSummaryDocument,
    StructuresDocument,
    ThresholdsDocument,
    TrendRow,
    TrendsDocument,
    WindowDocument,
    WindowKind,
    chart_name,
    estimate_payloads,
)
from ._modes import ModeMap
from ._payloads import (
    BEARING_TOPIC,
    ESTIMATE_LOADS_TOPIC,
    ESTIMATE_TOPIC,
    IMU_PLANAR_COLUMNS,
    NOMINAL_PERIOD_NS,
    PAYLOAD_FIELDS,
    SCHEMAS,
    TEMPERATURE_TOPIC,
    TRUTH_TOPIC,
    FieldSpec,
    Kind,
    RowLayout,
    TopicInfo,
    classify_topic,
    row_layout,
)
from ._rig import (
    DNV_RP_C203_CURVE_NAMES,
    EXTENSION_KEYS,
    DNV_RP_C203_ENVIRONMENTS,
    EN1993_DETAIL_CATEGORIES,
    EN1993_SHEAR_CATEGORIES,
    STEEL_YOUNGS_MODULUS_TEMPERATURE_COEFFICIENT,
    Beam,
    FatigueSettings,
    HotSpot,
    check_curve_spec,
    Orientation,
    PointMass,
    RigDescription,
    RigError,
    Sensor,
    SensorKind,
    StiffnessSegment,
    Support,
    load_rig,
    parse_rig,
)
from ._state import Peripheral, StateIndex, StateLayout
from ._ports import (
    MAX_PAGE, Lane, LanePool, NotSingleStructure, Page, ServicePort, ServiceStarting, StructureHost, StructureModel,
    StructurePort, StructureUnavailable, Waker,
)

__all__ = [
    "is_loopback",
    # the runtime's ports (the HTTP routers and the dashboard are typed against them)
    "MAX_PAGE", "Lane", "LanePool", "NotSingleStructure", "Page", "ServicePort", "ServiceStarting", "StructureHost", "StructureModel", "StructurePort", "StructureUnavailable", "Waker",
    # rig.json
    "Beam", "EXTENSION_KEYS", "Orientation", "PointMass", "RigDescription",
    "DNV_RP_C203_CURVE_NAMES", "DNV_RP_C203_ENVIRONMENTS", "EN1993_DETAIL_CATEGORIES", "EN1993_SHEAR_CATEGORIES",
    "FatigueSettings", "HotSpot", "check_curve_spec", "RigError", "Sensor", "SensorKind", "StiffnessSegment",
    "STEEL_YOUNGS_MODULUS_TEMPERATURE_COEFFICIENT", "Support", "load_rig", "parse_rig",
    # topics and payloads
    "BEARING_TOPIC", "ESTIMATE_LOADS_TOPIC", "ESTIMATE_TOPIC", "IMU_PLANAR_COLUMNS", "NOMINAL_PERIOD_NS", "PAYLOAD_FIELDS", "SCHEMAS",
    "TEMPERATURE_TOPIC", "TRUTH_TOPIC", "FieldSpec", "Kind", "RowLayout", "TopicInfo", "classify_topic", "row_layout",
    # state and modes
    "ModeMap", "Peripheral", "StateIndex", "StateLayout",
    # documents
    "CURVATURE_CHART", "SENSOR_STATES", "AidingChannelDocument", "AlarmCountsDocument", "AlarmDocument",
    "AlarmEvent", "AlarmEventDocument", "AlarmLevel", "AlarmsDocument", "ArchiveStatusDocument", "BaselineModeDocument",
    "BaselineRequestDocument", "BaselineStatusDocument", "ChartDocument", "ChartKind", "ChartLevelsDocument",
    "FATIGUE_CONDITIONS", "FatigueDocument", "HotSpotLoadsDocument", "LoadsWindowDocument", "StationLoadsDocument",
    "CurvatureDocument", "DegradedImuDocument", "ErrorDocument", "EstimateDocument", "EstimatorStatusDocument", "FlagDocument",
    "HealthDocument", "IngestErrorDocument", "IngestResultDocument", "LastEstimateDocument", "LiveEstimatesDocument", "Level", "LocationDocument", "ModeDocument",
    "ModelDocument", "NotificationStatusDocument", "PipelineStatusDocument", "RestCalibrationDocument", "SensorState",
    "ServiceStatusDocument", "SinkStatusDocument", "SourceStatusDocument", "SpectrumDocument", "StatusDocument",
    "StorageStatusDocument", "StructureState", "StructureSummaryDocument", "StructuresDocument", "ThresholdsDocument", "TrendRow", "TrendsDocument", "WindowDocument", "WindowKind",
    "chart_name", "estimate_payloads",
]
