"""The on-disk layout of a nuScenes-layout data set as CAMA Studio reads and writes it.

Standard nuScenes (what `nuscenes-devkit` reads):
    <root>/<version>/{scene,sample,sample_data,ego_pose,calibrated_sensor,sensor,log,map,
                      category,attribute,visibility,instance,sample_annotation}.json
    <root>/samples/<CHANNEL>/<file>.jpg     key-frame camera images (is_key_frame = true)
    <root>/sweeps/<CHANNEL>/<file>.jpg      the other camera images
    <root>/maps/<file>.png                  map.json's semantic prior (drivable area)
    <root>/can_bus/<scene>_<message>.json   CAN bus expansion: one list of dicts per message

Additions (absent in real nuScenes, optional for the loader):
    <root>/can_bus/<scene>_gnss.json        GNSS fixes (see GNSS_FIELDS)
    <root>/semantic/<image path>.png        per-image semantic mask (cama_pipeline.semantics ids, uint8)
    <root>/lane_instance/<image path>.png   per-image instance mask (uint16, class * 1000 + index)

`<image path>` is sample_data's `filename` with its extension replaced by `.png`
(e.g. `semantic/samples/CAM_FRONT/x__CAM_FRONT__1532.png`).

Conventions: translations in metres in the global frame, quaternions [w, x, y, z],
timestamps in microseconds; `calibrated_sensor` is ego_from_sensor, `ego_pose` is global_from_ego.
"""

CAMERA_CHANNELS: tuple[str, ...] = (
    "CAM_FRONT",
    "CAM_FRONT_RIGHT",
    "CAM_BACK_RIGHT",
    "CAM_BACK",
    "CAM_BACK_LEFT",
    "CAM_FRONT_LEFT",
)

CAMERA_MODALITY = "camera"
"""`sensor.modality` of a camera (the others are lidar and radar)."""

REQUIRED_TABLES: tuple[str, ...] = (
    "scene",
    "sample",
    "sample_data",
    "ego_pose",
    "calibrated_sensor",
    "sensor",
    "log",
)
"""Tables the loader cannot work without."""

OPTIONAL_TABLES: tuple[str, ...] = (
    "map",
    "category",
    "attribute",
    "visibility",
    "instance",
    "sample_annotation",
)
"""Tables nuScenes has that CAMA Studio writes (mostly empty) but does not need."""

TABLE_FIELDS: dict[str, tuple[str, ...]] = {
    "scene": (
        "token",
        "log_token",
        "nbr_samples",
        "first_sample_token",
        "last_sample_token",
        "name",
        "description",
    ),
    "sample": ("token", "timestamp", "prev", "next", "scene_token"),
    "sample_data": (
        "token",
        "sample_token",
        "ego_pose_token",
        "calibrated_sensor_token",
        "timestamp",
        "fileformat",
        "is_key_frame",
        "height",
        "width",
        "filename",
        "prev",
        "next",
    ),
    "ego_pose": ("token", "timestamp", "translation", "rotation"),
    "calibrated_sensor": ("token", "sensor_token", "translation", "rotation", "camera_intrinsic"),
    "sensor": ("token", "channel", "modality"),
    "log": ("token", "logfile", "vehicle", "date_captured", "location"),
    "map": ("token", "log_tokens", "category", "filename"),
}
"""Fields each record of a table must have (nuScenes names)."""

CAN_DIR = "can_bus"
SEMANTIC_DIR = "semantic"
INSTANCE_DIR = "lane_instance"

IMU_MESSAGE = "ms_imu"
"""100 Hz: utime, linear_accel [m/s^2, specific force in the ego frame], rotation_rate [rad/s, ego frame],
q [w, x, y, z] (the IMU's own attitude estimate, drifting in yaw)."""
IMU_FIELDS: tuple[str, ...] = ("utime", "linear_accel", "rotation_rate", "q")

WHEEL_MESSAGE = "zoe_veh_info"
"""100 Hz: utime, {FL,FR,RL,RR}_wheel_speed [rpm]; wheel radius in WHEEL_RADIUS_M."""
WHEEL_FIELDS: tuple[str, ...] = (
    "utime",
    "FL_wheel_speed",
    "FR_wheel_speed",
    "RL_wheel_speed",
    "RR_wheel_speed",
)
WHEEL_RADIUS_M = 0.305
"""nuScenes' Renault Zoe wheel radius, as the nuScenes CAN bus tutorial uses."""

GNSS_MESSAGE = "gnss"
"""utime, pos [x, y, z] global metres, std_m [east, north, up] reported 1-sigma, fix (bool)."""
GNSS_FIELDS: tuple[str, ...] = ("utime", "pos", "std_m", "fix")

CAN_MESSAGES: dict[str, tuple[str, ...]] = {
    IMU_MESSAGE: IMU_FIELDS,
    WHEEL_MESSAGE: WHEEL_FIELDS,
    GNSS_MESSAGE: GNSS_FIELDS,
}


def can_file_name(scene_name: str, message: str) -> str:
    """File name of one CAN message list of one scene, e.g. `scene-0001_ms_imu.json`."""
    return f"{scene_name}_{message}.json"


def mask_relpath(mask_dir: str, image_filename: str) -> str:
    """Relative path of the mask of an image (`image_filename` as in sample_data)."""
    stem = image_filename.rsplit(".", 1)[0]
    return f"{mask_dir}/{stem}.png"
