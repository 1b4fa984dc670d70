/* headway.h - the only door between the C++ core and its callers (Python through cffi).
 *
 * Rules of this door:
 *  - Opaque handles and plain structs only; the caller allocates every result buffer.
 *  - Every function returns an hw_status (0 = HW_OK). On failure, hw_last_error() returns a message
 *    for the calling thread that names what was wrong; hw_error_message(code) names the code.
 *  - No C++ exception ever crosses this door: each entry point catches everything.
 *  - "Not available" floats are NaN, "not available" ids and indices are -1. A field that a later
 *    stage fills stays not-available until that stage runs (see the comment on each field).
 *  - Configuration and frame-source descriptions are JSON objects (the Python supervisor validates
 *    the YAML configuration and hands the core its JSON form).
 *
 * The part between HW_CDEF_BEGIN and HW_CDEF_END is read verbatim by the cffi build script, so it
 * holds plain declarations and integer #defines only.
 */
#ifndef HEADWAY_H
#define HEADWAY_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* HW_CDEF_BEGIN */
#define HW_ABI_VERSION 14

#define HW_MAX_TRACKS 64
#define HW_MAX_LANES 8
#define HW_LANE_POINTS 12
#define HW_MAX_STAGES 16
#define HW_STAGE_NAME_LEN 16

/* Status codes returned by every call. */
typedef enum {
    HW_OK = 0,
    HW_ERR_INVALID_ARGUMENT = 1, /* a null pointer, a wrong size, a frame of the wrong shape */
    HW_ERR_CONFIG = 2,           /* the configuration JSON is malformed or a value is out of range */
    HW_ERR_SOURCE = 3,           /* the frame source cannot be opened (missing device, not a video) */
    HW_ERR_STATE = 4,            /* call not allowed now (start while running, push without a push source) */
    HW_ERR_TIMEOUT = 5,          /* pop: no result within the timeout */
    HW_ERR_END_OF_STREAM = 6,    /* pop: the source has ended and every result was popped */
    HW_ERR_INTERNAL = 7          /* an unexpected exception inside the core (message says which) */
} hw_status;

/* What the road-plane motion estimate (parallax preset) did in a frame. */
typedef enum {
    HW_ROAD_NONE = 0,      /* no estimate: another preset, the first frames, or lost after a long gap */
    HW_ROAD_ACCEPTED = 1,  /* a measured homography passed the gate and updated the filter */
    HW_ROAD_PREDICTED = 2  /* no acceptable measurement: the filter's prediction carries on (coasting) */
} hw_road_motion;

/* What self-calibration is doing (geometry/self_calibration.hpp, CalibrationState). */
typedef enum {
    HW_CALIB_OFF = 0,        /* self_calibration.enabled false: the configured camera as it is */
    HW_CALIB_LEARNING = 1,   /* an uncertainty above self_calibration.converged_sigma_* */
    HW_CALIB_CONVERGED = 2,  /* every uncertainty within them */
    HW_CALIB_AT_LIMIT = 3    /* an estimate held at its configured bound (max_*_dev) */
} hw_calib_state;

/* FCW levels (the warning state machine runs in the supervisor, which has the ego speed, brake and turn
 * signals; the core reports no level). */
typedef enum { HW_FCW_NONE = 0, HW_FCW_PREWARNING = 1, HW_FCW_WARNING = 2 } hw_fcw_level;

/* State of the frame source feeding a running loop. */
typedef enum {
    HW_SOURCE_IDLE = 0,         /* not started */
    HW_SOURCE_RUNNING = 1,      /* delivering frames */
    HW_SOURCE_RECONNECTING = 2, /* a live source lost its device and is retrying with back-off */
    HW_SOURCE_ENDED = 3,        /* a file or folder reached its end */
    HW_SOURCE_FAILED = 4        /* gave up (e.g. a recording that cannot be decoded at all) */
} hw_source_state;

/* Health event bits, set in hw_frame_result.events for the frame where they happened and
 * accumulated in hw_health.event_counts. */
#define HW_EVENT_DECODE_ERROR 1   /* a frame could not be decoded and was skipped */
#define HW_EVENT_SOURCE_LOST 2    /* a live device stopped delivering (unplugged, read failure) */
#define HW_EVENT_RECONNECTED 4    /* a live device came back */
#define HW_EVENT_SIZE_CHANGED 16  /* a frame of another size than the first one was skipped */
#define HW_EVENT_CONCEALED 32     /* this frame was decoded with errors the decoder concealed */

typedef struct {
    int32_t id;            /* stable track id, >= 1 */
    int32_t confirmed;     /* 1 once the tracker confirmed it (M hits), else 0 */
    int32_t age_frames;    /* frames since the track was created */
    float left, top, right, bottom; /* box in pixels of the processed frame */
    float confidence;      /* 0..1 */
    float vx_px_s, vy_px_s;         /* image velocity of the bottom centre, px/s */
    float range_m;         /* flat-road range to the rear face (geometry stage), NaN if n/a */
    float range_sigma_m;   /* 1-sigma range uncertainty from the bottom-row uncertainty, NaN if n/a */
    float lateral_m;       /* lateral offset of the rear centre, right positive, NaN if n/a */
    float range_rate_mps;  /* d(range)/dt, negative when closing, NaN if n/a */
    float range_accel_mps2;/* d2(range)/dt2, negative when the closing speeds up (lead braking), NaN if n/a */
    float ttc_s;           /* range-based time to collision, NaN if n/a or not closing */
    float ttc_scale_s;     /* scale-based TTC = w / (dw/dt), NaN if n/a or not closing */
    int32_t lane_index;    /* 0 ego lane, -1 left, +1 right ...; -1000 if unknown */
    int32_t in_path;       /* 1 in the ego path, 0 not, -1 unknown */
} hw_track;

typedef struct {
    /* a lane boundary as a segment in the image: bottom point and top point, px */
    float x_bottom, y_bottom, x_top, y_top;
    int32_t position;      /* -1 ego left, +1 ego right; -2 / +2 the adjacent lanes' outer boundaries;
                            * -3 / +3 one lane further out (only with lanes.outer_lanes) */
    int32_t observed;      /* 1 measured in this frame, 0 carried over by lane tracking */
    /* the boundary as it bends with the road: n_points image points from the bottom point up to
     * lanes.curve_far_range_m (beyond the top point the fitted curve is extrapolated), spaced evenly in
     * log range (denser far away, where the bend is); straight lines between them */
    int32_t n_points;
    float px[HW_LANE_POINTS], py[HW_LANE_POINTS];
} hw_lane;

typedef struct {
    char name[HW_STAGE_NAME_LEN];
    float ms;
} hw_stage_time;

/* One detection: a box of the detection stage (hw_frame_result.detections, hw_pipeline_detect). */
typedef struct {
    float left, top, right, bottom; /* px */
    float confidence;               /* 0..1 */
} hw_box;

typedef struct {
    int64_t frame_number;  /* 0-based number of the frame from its source */
    double t_capture_s;    /* capture timestamp (monotonic clock for live sources, media time otherwise) */
    double t_done_s;       /* monotonic clock when processing finished */
    int32_t width, height;
    int32_t events;        /* HW_EVENT_* bits for this frame */
    int32_t full_detection;/* 1 if the tracker took a full detection this frame (found on detections_frame) */
    int32_t n_tracks;
    hw_track tracks[HW_MAX_TRACKS];
    /* the detection stage's vehicles the tracker took this frame (full_detection), strongest first, found on
     * frame detections_frame (this one, or phd.detect_lag frames earlier when the detection ran on its worker
     * thread); the same list hw_pipeline_detect (detector NULL) gives for that frame's image alone */
    int64_t detections_frame; /* -1 when none */
    int32_t n_detections;
    hw_box detections[HW_MAX_TRACKS];
    int32_t n_lanes;
    hw_lane lanes[HW_MAX_LANES];
    float vanishing_x, vanishing_y; /* NaN if no lane model yet */
    float lane_width_m;    /* ego-lane width at the bottom row, m; NaN unless both ego boundaries are known */
    float lane_offset_m;   /* the car's centre right of the ego lane's centre, m; NaN unless both are known */
    int32_t lanes_certain; /* 1 when the lane model is believed: both ego boundaries have paint along the road
                            * (lanes.evidence_min); the road prior and the lead selection use only such a model */
    float horizon_row;     /* horizon row used for range, NaN if n/a */
    int32_t lead_id;       /* -1 if no lead */
    int32_t n_stages;
    hw_stage_time stages[HW_MAX_STAGES];
    float total_ms;
    /* image health on a sparse grid: mean gray, its standard deviation (near 0 = blinded), mean absolute
     * change since the previous frame (0 = frozen; NaN on the first frame) */
    float image_mean, image_stddev, image_change;
    /* the road plane's motion from the previous frame to this one (parallax preset): hw_road_motion, the
     * frames the prediction has carried on without an accepted measurement, and the filtered homography
     * (pixels, previous -> current, row-major; NaN when road_motion is HW_ROAD_NONE) */
    int32_t road_motion;
    int32_t road_coast_frames;
    float road_homography[9];
    /* how well road_homography aligns the road (homography.measure_residual true, else NaN; NaN without an
     * estimate): mean |difference|, gray levels, over the road pixels (the ego lane up to 40 m, or the road area
     * without a lane model; outside this frame's detections and the bonnet) between this frame and the previous
     * one warped with it, their smooth brightness change taken out; the same without warping; and warped with
     * the brightness change left in */
    float road_residual, road_residual_unaligned, road_residual_raw;
    /* the camera as self-calibration has it (the configured one when self_calibration.enabled is false):
     * pitch (deg, down positive), yaw (deg, right positive), height (m) and their 1-sigma uncertainties,
     * the frames whose lane measurement was used, 1 when self-calibration runs */
    float calib_pitch_deg, calib_yaw_deg, calib_height_m;
    float calib_pitch_sigma_deg, calib_yaw_sigma_deg, calib_height_sigma_m;
    int32_t calib_updates;
    int32_t calib_active;
    int32_t calib_state;   /* hw_calib_state */
} hw_frame_result;

typedef struct {
    int32_t running;          /* 1 while the real-time thread runs */
    int32_t source_state;     /* hw_source_state */
    int64_t frames_captured;  /* frames read from the source */
    int64_t frames_processed;
    int64_t results_dropped;  /* results dropped because the queue to the caller was full */
    int64_t frames_pushed_dropped; /* pushed frames dropped because the push queue was full */
    int64_t decode_errors;
    int64_t source_losses;
    int64_t reconnects;
    double last_frame_t_s;    /* capture time of the last frame, NaN before the first */
    double last_progress_s;   /* monotonic time the loop last finished a frame, NaN before */
    double last_alive_s;      /* monotonic time the loop thread last went round (also while waiting for
                                 frames or reconnecting): the watchdog's sign of life, NaN if not running */
    float last_total_ms;
    int32_t queue_depth;
    int32_t queue_capacity;
} hw_health;

typedef struct hw_pipeline hw_pipeline;

int hw_abi_version(void);
const char *hw_error_message(int code);
/* Message of the last failed call on this thread ("" if none). Valid until the next call. */
const char *hw_last_error(void);
/* Monotonic clock of the core, seconds (the clock of t_done_s and live capture timestamps). */
double hw_monotonic_s(void);

/* config_json: the full configuration (see app/config.py); NULL or "{}" for the defaults. */
int hw_pipeline_create(const char *config_json, hw_pipeline **out);
void hw_pipeline_destroy(hw_pipeline *p);
/* The effective configuration (every key the core knows, with the value in use) as JSON, written
 * into buf with its terminating zero. *needed receives the size required; HW_ERR_INVALID_ARGUMENT
 * if buf_len is smaller. p NULL: every key described ({section: {key: {default, type, min, max, doc}}})
 * "moved_keys": {"old_section.key": "new_section.key"} and "presets": {name: {"detectors": [...],
 * "tracker": "...", "keys": {section: {key: value}}}} (the keys a preset sets unless the configuration does),
 * "default_preset": the preset of a configuration file that names none. */
int hw_pipeline_config(hw_pipeline *p, char *buf, int32_t buf_len, int32_t *needed);

/* Offline: run the same per-frame code as the real-time loop on one 8-bit gray frame.
 * Not allowed while the loop runs. t_s must not go backwards (HW_ERR_INVALID_ARGUMENT). */
int hw_pipeline_process(hw_pipeline *p, const uint8_t *gray, int32_t width, int32_t height,
                        int32_t stride, double t_s, hw_frame_result *out);
/* What hw_pipeline_detect found besides the boxes. */
typedef struct {
    int32_t n_detections;  /* detections the stage gave (all of them: may be more than the cap asked for) */
    float horizon_row;     /* the horizon row they were found with (the configured camera's) */
    int32_t n_stages;      /* wall time of the stage's sub-stages (lanes, the detector parts' own) */
    hw_stage_time stages[HW_MAX_STAGES];
    float total_ms;
} hw_detect_info;

/* Offline: the detection stage on one 8-bit gray image alone, without touching any tracking state (what
 * `headway detect` writes): the detector part named `detector` (one of the configuration's pipeline.detectors
 * choices, built from this configuration), or the pipeline's own detection stage (its composition's detector parts,
 * fused as in a tracked pipeline) when detector is NULL or "". The lane markings of this image alone give the road
 * context. Every detection the stage gives, in its order (strongest first), without the HW_MAX_TRACKS cap of
 * hw_frame_result (the cascade with cascade.nms_iou 1 gives ~150 groups on a 1280x720 image): copies at most cap of
 * them into out (NULL allowed when cap is 0) and info->n_detections receives how many there are: call again with a
 * larger out when it is > cap. HW_ERR_INVALID_ARGUMENT for an unknown name or a part that needs the road's motion
 * (parallax: two frames). */
int hw_pipeline_detect(hw_pipeline *p, const char *detector, const uint8_t *gray, int32_t width, int32_t height,
                       int32_t stride, hw_box *out, int32_t cap, hw_detect_info *info);
/* The car's own motion from the vehicle bus (NaN = not available): used for the ego path when the
 * lanes are missing. Allowed while the loop runs; takes effect from the next frame. */
int hw_pipeline_set_ego_motion(hw_pipeline *p, double speed_mps, double yaw_rate_rps);
/* Forget all state (tracks, lane model) as if newly created. Not allowed while the loop runs. */
int hw_pipeline_reset(hw_pipeline *p);

/* source_json: {"kind": "v4l2"|"firewire"|"video"|"folder"|"push", ...} (see app/config.py).
 * Opens the source (HW_ERR_SOURCE with a message if it cannot) and starts the real-time thread. */
int hw_pipeline_start(hw_pipeline *p, const char *source_json);
/* Stops and joins the thread; results still queued can be popped afterwards. Idempotent. */
int hw_pipeline_stop(hw_pipeline *p);
/* Wait up to timeout_ms for the next result (the GIL is released by cffi meanwhile). */
int hw_pipeline_pop(hw_pipeline *p, int32_t timeout_ms, hw_frame_result *out);
/* Push source only: copy one frame into the core. gray: channels 1; bgr: channels 3. Returns
 * HW_ERR_INVALID_ARGUMENT if the size differs from the source's configured size. */
int hw_pipeline_push(hw_pipeline *p, const uint8_t *data, int32_t width, int32_t height,
                     int32_t channels, int32_t stride, double t_s);
/* Push source only: no more frames; the loop ends after the queued ones. */
int hw_pipeline_push_end(hw_pipeline *p);
int hw_pipeline_health(hw_pipeline *p, hw_health *out);

/* HW_CDEF_END */

#ifdef __cplusplus
}
#endif

#endif /* HEADWAY_H */
