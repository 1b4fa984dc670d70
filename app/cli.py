"""`headway`: the command line. Each subcommand lives in its own module; this file only parses
arguments and turns every expected failure into one clear line on stderr and a non-zero exit."""
from __future__ import annotations

import argparse
import os
import sys

# OpenCV and FFmpeg print their own warnings (a file that is not a video, a camera index that does not
# open) before ours says the same in one line; keep only their errors.
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


def _cmd_sim(args) -> int:
    from app.sim import load_scenario, write_scenario

    sc = load_scenario(args.scenario)
    from tqdm import tqdm

    with tqdm(total=None, desc=sc.name, unit="frame", file=sys.stderr, disable=not sys.stderr.isatty(),
              leave=False) as bar:
        def progress(i, n):
            bar.total = n
            bar.update(1)

        info = write_scenario(sc, args.out, video=args.video, progress=progress)
    print(f"{sc.name}: {info.get('n_frames')} frames -> {args.out}")
    return 0


def _cmd_replay(args) -> int:
    from app.replay import replay

    s = replay(args.source, config_path=args.config, fps=args.fps, out_video=args.out_video,
               tracks_path=args.tracks, can_in=args.can_in, can_out=args.can_out)
    print(s.text())
    return 0


def _cmd_status(args) -> int:
    import json
    import os

    from app.supervisor.status_file import STOPPED, UNKNOWN, StatusFileError, assess, format_status, read_status

    path = args.file
    if path is None:
        path = os.environ.get("HEADWAY_STATUS_FILE")
    if path is None:
        from app import config as configuration

        cfg = configuration.load(args.config if os.path.exists(args.config) else None)
        path = cfg["service"]["status_file"]
    try:
        st = read_status(path)
    except StatusFileError as exc:
        print(f"state: {UNKNOWN}\nheadway: {exc}")
        return 3
    print(json.dumps(st, indent=1) if args.json and st else format_status(st, path))
    if st is None:
        return 1
    # 0 while the service runs (ok, degraded, fault: its own words); 3 when it does not, as systemctl's
    # "not running": stopped, or unknown (gone, stale, future or malformed time stamp)
    return 0 if assess(st)[0] not in (UNKNOWN, STOPPED) else 3


def _cmd_config(args) -> int:
    from app import config as configuration

    if args.action == "default":
        print(configuration.default_yaml())
        return 0
    if args.action == "doc":
        print(configuration.markdown())
        return 0
    cfg = configuration.load(args.file)
    from app.config_check import problems

    # everything that would stop the service, opened as the service opens it; the first problem is the line
    found = problems(cfg, skip_absent_devices=args.skip_absent_devices)
    if found:
        print(f"headway: configuration error: {configuration.error_line(found[0], args.file)}", file=sys.stderr)
        return 2
    print(f"{args.file}: ok")
    return 0


def _cmd_train(args) -> int:
    if args.model == "proposals":   # the learned first stage (detector part proposals)
        from app.train import proposals

        if args.epochs < 1 or args.batch < 1 or args.threads < 1 or args.input_width < 16:
            raise ValueError(f"--epochs {args.epochs} --batch {args.batch} --threads {args.threads} --input-width "
                             f"{args.input_width}: give at least 1 epoch, 1 image a batch, 1 thread and 16 px")
        log = _line_logger(args.log)
        try:
            proposals.train(args.data, args.out, epochs=args.epochs, seed=args.seed, input_width=args.input_width,
                            batch=args.batch, lr=args.lr, cache=args.cache, limit=args.limit, log=log,
                            threads=args.threads)
        finally:
            log.close()
        return 0
    if args.model == "verifier":
        from app import config as configuration
        from app.eval.tusimple_boxes import tusimple_config
        from app.train import verifier

        cfg = configuration.load(args.config) if args.config else tusimple_config(configuration.load(None))
        if args.out.endswith(".onnx"):   # the convolutional verifier, run by cv::dnn in the core
            from app.train import verifier_cnn

            try:
                channels = tuple(int(c) for c in args.channels.split("/"))
            except ValueError:
                channels = ()
            if len(channels) != 3 or min(channels) < 1:
                raise ValueError(f"--channels {args.channels!r}: give three conv widths, e.g. 8/16/32")
            log = _line_logger(args.log)
            try:
                verifier_cnn.train(args.data, args.cascade, args.out, cfg, every=args.every or 1, channels=channels,
                                   hidden=args.hidden, epochs=args.epochs or 6, decay=args.decay, seed=args.seed,
                                   cache=args.cache, compare_hog=args.compare_hog, log=log, box=not args.no_box,
                                   near=args.near, margin=args.margin, neg_share=args.neg_share)
            finally:
                log.close()
            return 0
        verifier.train(args.data, args.cascade, args.out, cfg, every=args.every or 4, hidden=args.hidden,
                       epochs=args.epochs or 12, decay=args.decay, seed=args.seed)
        return 0
    # `headway train cascade`: the Viola-Jones trainer (app/train/cascade, independent of the rest of app)
    from app.train.cascade import TrainParams, train

    try:
        w, h = (int(v) for v in args.window.lower().split("x"))
    except ValueError:
        raise ValueError(f"--window {args.window!r}: give WIDTHxHEIGHT in pixels, e.g. 30x20") from None
    if min(w, h) < 6:
        raise ValueError(f"--window {args.window}: at least 6 px each way (OpenCV ignores a 1-px border)")
    p = TrainParams(width=w, height=h, stages=args.stages, num_pos=args.num_pos, num_neg=args.num_neg,
                    features=args.features, min_hit_rate=args.min_hit_rate, max_false_alarm=args.max_false_alarm,
                    seed=args.seed, max_minutes=args.max_minutes, resume=args.resume or "", booster=args.boost,
                    min_aspect=args.min_aspect, max_aspect=args.max_aspect, scan_band=_scan_band(args.scan_band))
    if not 0 <= p.min_aspect < p.max_aspect:
        raise ValueError(f"--min-aspect {p.min_aspect:g} --max-aspect {p.max_aspect:g}: give 0 <= min < max (box "
                         f"width / height)")
    log = _line_logger(args.log)
    try:
        train(args.data, args.out, p, log=log)
    finally:
        log.close()
    return 0


def _scan_band(text: str | None) -> tuple:
    """`--scan-band ROW,HEIGHT_M[,MIN_M,MAX_M]` as the trainer's tuple; () when not given."""
    if not text:
        return ()
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) not in (2, 4) or v[1] <= 0 or (len(v) == 4 and not 0 < v[2] < v[3]):
        raise ValueError(f"--scan-band {text!r}: give ROW,HEIGHT_M or ROW,HEIGHT_M,MIN_M,MAX_M (horizon row in px, "
                         f"camera height in m, the lowest and tallest vehicle in m, lowest first), e.g. 344,1.8")
    return v


class _line_logger:
    """Prints a training log line and, with a path, also appends it to that file as it comes."""

    def __init__(self, path: str | None):
        self.fh = open(path, "w") if path else None

    def __call__(self, line: str) -> None:
        print(line, flush=True)
        if self.fh:
            self.fh.write(line + "\n")
            self.fh.flush()

    def close(self) -> None:
        if self.fh:
            self.fh.close()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="headway", description="Camera-based vehicle detection, tracking and "
                                                            "forward-collision warning.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("demo", help="render the built-in scenario, run the full pipeline, write ./headway-demo/")
    s.add_argument("--out", default="headway-demo", help="output folder (default ./headway-demo)")
    s.add_argument("--scenario", default=None, help=argparse.SUPPRESS)
    s.add_argument("--config", default=None, help=argparse.SUPPRESS)

    s = sub.add_parser("sim", help="render a synthetic scenario: frames, ground truth, ego-speed CAN log")
    s.add_argument("scenario", help="scenario name (see app/sim/scenarios) or a scenario YAML file")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--video", action="store_true", help="write video.mp4 instead of a PNG per frame")

    s = sub.add_parser("replay", help="run a video file, an image folder or a scenario through the pipeline")
    s.add_argument("source", help="video file, image folder (give --fps) or scenario")
    s.add_argument("--config", help="configuration YAML (default: built-in defaults)")
    s.add_argument("--fps", type=float, help="frame rate of an image folder, or to override a video's own "
                                              "(0.1 to 1000 frames/s)")
    s.add_argument("--out-video", help="write an annotated video here (.mp4)")
    s.add_argument("--tracks", help="write the tracks here (.jsonl, one line per frame)")
    s.add_argument("--can-in", help="vehicle CAN log replayed on the frame clock (.log candump, .asc, .blf); "
                                    "a scenario uses its own ego-speed log when not given")
    s.add_argument("--can-out", help="write every CAN frame Headway sends here (.log, .asc or .blf)")

    s = sub.add_parser("detect", help="single-image vehicle detection to JSON")
    s.add_argument("images", nargs="+", help="image files")
    s.add_argument("--out", required=True, help="output JSON file")
    s.add_argument("--config", help="configuration YAML")
    s.add_argument("--preset", choices=("default", "paper004", "thesis"),
                   help="the preset whose detection stage runs (default: the configuration's, `default`)")
    s.add_argument("--min-score", type=float, default=None,
                   help="write only detections scoring at least this (0-1); default: the preset's operating point "
                        "(precision 0.85 on held-out training images: docs/cascade.md; thesis: every detection); 0 "
                        "writes every detection")

    s = sub.add_parser("run", help="run on the live camera of the configuration until SIGINT/SIGTERM "
                                   "(the service, in a terminal)")
    s.add_argument("--config", help="configuration YAML (source:, camera:, can: sections)")
    s.add_argument("--tracks", help="also write the tracks here (.jsonl)")

    s = sub.add_parser("service", help="the in-vehicle daemon systemd runs (systemd/headway.service)")
    s.add_argument("--config", default="/etc/headway/config.yaml", help="configuration YAML")

    s = sub.add_parser("status", help="the running service's health, for a person at a shell")
    s.add_argument("--file", default=None, help="status file (default: service.status_file of --config)")
    s.add_argument("--config", default="/etc/headway/config.yaml", help="configuration YAML")
    s.add_argument("--json", action="store_true", help="print the raw JSON")

    s = sub.add_parser("install-service", help="install the systemd unit, the CAN set-up and /etc/headway/config.yaml")
    s.add_argument("--root", default="/", help="install into this root folder (default /; for packaging and tests)")
    s.add_argument("--bench", action="store_true", help="also set up a virtual CAN interface vcan0")
    s.add_argument("--no-enable", action="store_true", help="do not run systemctl (no daemon-reload, no enable)")

    s = sub.add_parser("bench", help="per-stage median and p99 ms per frame")
    s.add_argument("--scenario", default="dense_traffic", help="scenario whose frames are timed")
    s.add_argument("--preset", help="pipeline preset (default: the configuration's); with --images, the preset whose "
                                    "detection stage is timed, as `headway detect --preset`")
    s.add_argument("--width", type=int, default=640)
    s.add_argument("--height", type=int, default=480)
    s.add_argument("--repeats", type=int, default=3, help="passes over the scenario (with --images: over the images)")
    s.add_argument("--config", help="configuration YAML")
    s.add_argument("--json", action="store_true", help="print JSON instead of a table")
    s.add_argument("--latency", action="store_true",
                   help="measure capture-to-CAN latency and the supervisor's CPU per frame through the live loop")
    s.add_argument("--seconds", type=float, default=10.0, help="length of the --latency run")
    s.add_argument("--fps", type=float, default=None,
                   help="also feed the frames at this camera rate and report each frame's latency and the detection's "
                        "age (default: the configuration's source.fps; 0: back to back only)")
    s.add_argument("--images", nargs="+", metavar="PATH",
                   help="time `headway detect` instead, per image and part (reading and decoding, lanes, the cascade's "
                        "scan, its verifier, the shadows), on these image files or folders of images")
    s.add_argument("--limit", type=int, default=100, help="with --images: the first this many images (0 = all)")

    s = sub.add_parser("eval", help="measure a pipeline on the synthetic suite and the real data; JSON + markdown")
    s.add_argument("--pipeline", default="default",
                   help="preset to evaluate: default, thesis, parallax, paper004 (default: default); several separated "
                        "by commas (e.g. default,thesis,parallax,paper004) are evaluated one after another, each into "
                        "OUT/PRESET/, and set side by side in OUT/compare.md")
    s.add_argument("--parts", help="comma-separated subset of synthetic,tusimple,lanes,range,fcw,road_motion,real_fcw,cost "
                                         "(default all)")
    s.add_argument("--scenarios", help="comma-separated scenario names (default: the whole suite)")
    s.add_argument("--data", default="../shared/data", help="real data folder (default ../shared/data)")
    s.add_argument("--out", help="report folder (default reports/eval-PIPELINE; with several presets "
                                 "reports/eval-A-B-...)")
    s.add_argument("--config", help="configuration YAML")
    s.add_argument("--workers", type=int, help="run the synthetic and FCW scenarios on a local Dask cluster of N "
                                               "worker processes (docs/fleet.md)")
    s.add_argument("--scheduler", help="... or on an existing Dask cluster (tcp://HOST:8786)")

    # ---- headway fleet (app/fleet/) ----
    s = sub.add_parser("fleet", help="replay many drives in parallel on Dask (local or an existing cluster); "
                                     "one report; --compare two runs")
    s.add_argument("manifest", nargs="?", help="manifest YAML: one entry per drive (docs/fleet.md)")
    s.add_argument("--out", help="output folder: drives/NAME/ per drive, report.md, report.json")
    s.add_argument("--scheduler", help="address of an existing Dask scheduler, e.g. tcp://HOST:8786 "
                                       "(default: a local cluster on this machine)")
    s.add_argument("--workers", type=int, help="local cluster: worker processes (default: one per core)")
    s.add_argument("--config", help="configuration YAML under every drive's own overrides")
    s.add_argument("--compare", nargs=2, metavar=("OLD_DIR", "NEW_DIR"),
                   help="compare two fleet runs' outputs drive by drive (FCW events, tracks, metrics, CAN)")
    # ---- end fleet ----

    s = sub.add_parser("train", help="train a learned model from annotated images")
    ts = s.add_subparsers(dest="model", required=True, metavar="MODEL")
    t = ts.add_parser("cascade", help="a Viola-Jones Haar cascade (OpenCV cascade XML) for vehicles")
    t.add_argument("--data", nargs="+", required=True,
                   help="folders with annotation.json in the TuSimple velocity format (every vehicle boxed)")
    t.add_argument("--out", required=True, help="cascade XML written after every stage")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--window", default="30x20", help="window WIDTHxHEIGHT, px (default 30x20)")
    t.add_argument("--stages", type=int, default=20, help="most stages (default 20)")
    t.add_argument("--num-pos", type=int, default=3000, help="positives per stage (default 3000)")
    t.add_argument("--num-neg", type=int, default=3000, help="negatives per stage (default 3000)")
    t.add_argument("--features", type=int, default=1500, help="random candidate features per stage (default 1500)")
    t.add_argument("--min-hit-rate", type=float, default=0.995, help="per stage (default 0.995)")
    t.add_argument("--max-false-alarm", type=float, default=0.5, help="per stage (default 0.5)")
    t.add_argument("--max-minutes", type=float, default=55.0, help="no stage starts after this (default 55)")
    t.add_argument("--resume", help="a cascade XML written by this trainer: keep its stages and train more")
    t.add_argument("--min-aspect", type=float, default=0.0,
                   help="boxes narrower than this (width / height) are not positives (default 0; one view only)")
    t.add_argument("--max-aspect", type=float, default=3.0,
                   help="boxes wider than this (width / height) are not positives (default 3: long side views)")
    t.add_argument("--boost", choices=["gentle", "discrete"], default="gentle",
                   help="gentle: Gentle AdaBoost, real-valued stump leaves (default, the shipped model); discrete: "
                        "Discrete AdaBoost as in paper 004, leaves +-alpha (docs/cascade.md compares them)")
    t.add_argument("--scan-band", metavar="ROW,HEIGHT_M[,MIN_M,MAX_M]",
                   help="negatives only from the rows the cascade stage scans for each window size: the camera's "
                        "horizon row (px) and height (m), and the lowest and tallest vehicle (default 1.0,4.5 m); "
                        "TuSimple's camera: 344,1.8 (default: negatives from anywhere in the image)")
    t.add_argument("--log", help="also write the per-stage log here")
    t = ts.add_parser("proposals", help="the learned first stage: a small fully convolutional network giving the "
                      "vehicles' centres and boxes (ONNX for the detector part proposals; needs pip install '.[train]')")
    t.add_argument("--data", nargs="+", required=True, help="training folders (annotation.json, every vehicle boxed)")
    t.add_argument("--out", required=True, help="the network's ONNX, written after every epoch")
    t.add_argument("--epochs", type=int, default=6, help="passes over the fitted images (default 5, the shipped model's)")
    t.add_argument("--batch", type=int, default=16, help="images a batch (default 16)")
    t.add_argument("--lr", type=float, default=2e-3, help="Adam's first learning rate, falling linearly to 0 (default 2e-3)")
    t.add_argument("--input-width", type=int, default=320, help="px: the images reduced to this width (default 320)")
    t.add_argument("--limit", type=int, default=0, help="only the first N images (0 = all; for a quick check)")
    t.add_argument("--threads", type=int, default=2, help="CPU threads JAX may use (default 2)")
    t.add_argument("--cache", help=".npz keeping the reduced images between runs (made if absent; outside the repository)")
    t.add_argument("--log", help="also write the per-epoch log here")
    t.add_argument("--seed", type=int, default=0)
    t = ts.add_parser("verifier", help="a network judging the cascade's detections: a small CNN on the box's crop "
                      "(--out X.onnx, needs pip install '.[train]') or HOG + one hidden layer (--out X.yml[.gz])")
    t.add_argument("--data", nargs="+", required=True, help="training folders (annotation.json, as for the cascade)")
    t.add_argument("--cascade", required=True, help="the cascade XML whose detections are judged")
    t.add_argument("--out", required=True, help="verifier model: .onnx = the CNN, .yml or .yml.gz = HOG network")
    t.add_argument("--every", type=int, help="use every N-th image (default: 1 for the CNN, 4 for HOG)")
    t.add_argument("--hidden", type=int, default=64, help="hidden units (default 64)")
    t.add_argument("--epochs", type=int, help="passes over the samples (default: 6 for the CNN, 12 for HOG)")
    t.add_argument("--channels", default="8/16/32", help="CNN: widths of its three conv layers (default 8/16/32)")
    t.add_argument("--cache", help="CNN: .npz keeping the cascade's labelled crops between runs (made if absent)")
    t.add_argument("--compare-hog", action="store_true",
                   help="CNN: also fit the HOG verifier on the same images and log both on the same held-out boxes")
    t.add_argument("--log", help="CNN: also write the training log here")
    t.add_argument("--no-box", action="store_true",
                   help="CNN: without the box output (the refined box the core reports before its suppression)")
    t.add_argument("--near", choices=("negative", "ignore"), default="negative",
                   help="CNN: detections at IoU 0.3-0.5 with an annotated box are others (default) or left out of "
                        "the classification (they still teach the box output)")
    t.add_argument("--margin", type=float, default=0.1,
                   help="CNN: of the box's size added each side of its crop (default 0.1; the core crops a network "
                        "with a box output with BOX_MARGIN, verifier_onnx.py)")
    t.add_argument("--neg-share", type=float, default=1.0,
                   help="CNN: share of the plain others (IoU < 0.3, ~90 %% of the samples) each epoch sees, drawn "
                        "afresh and weighted up so the loss is the same; 1 = all (default); 0.3 makes an epoch "
                        "~2.4x faster (docs/cascade.md, 'Session 13')")
    t.add_argument("--decay", type=float, default=1e-4, help="L2 weight decay (default 1e-4)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--config", help="configuration YAML with the images' camera (default: the TuSimple camera)")

    s = sub.add_parser("calibrate", help="camera intrinsics and lens distortion from chessboard photos, or the "
                                         "mounting (pitch, yaw, height) from a drive (--from-video) -> YAML")
    s.add_argument("images", nargs="*", help="chessboard photos from the camera, the board in different poses")
    s.add_argument("--board", default="9x6", help="inner corners per row x per column (default 9x6)")
    s.add_argument("--from-video", metavar="CLIP",
                   help="a drive on a marked road (video file or image folder): self-calibration's pitch, yaw and "
                        "height with their sigmas, written into the camera section of --config's copy")
    s.add_argument("--config", help="with --from-video: the configuration with the camera's intrinsics (and height)")
    s.add_argument("--fps", type=float, help="with --from-video: an image folder's frame rate")
    s.add_argument("--out", required=True, help="write the configuration here (.yaml)")

    s = sub.add_parser("config", help="check a configuration file, or print the documented defaults")
    cs = s.add_subparsers(dest="action", required=True, metavar="ACTION")
    c = cs.add_parser("check", help="validate FILE and open what the service opens (models, output files, CAN "
                                    "interface, source); prints the first problem in one line and exits 2")
    c.add_argument("file")
    c.add_argument("--skip-absent-devices", action="store_true",
                   help="do not fail on a camera that is not on this machine (checking a car's file elsewhere)")
    cs.add_parser("default", help="print the default configuration with every key documented")
    cs.add_parser("doc", help="print the configuration reference as markdown (docs/CONFIG.md)")
    return p


def _keep_inputs(args, images: list[str]) -> None:
    """OutputPathError if --out names one of the command's input images or its --config."""
    from app.output_files import check_outputs

    inputs = {f"input {i + 1}": p for i, p in enumerate(images)}
    check_outputs({"--out": args.out}, {**inputs, "--config": getattr(args, "config", None)})


def _dispatch(args) -> int:
    if args.command == "demo":
        from app import demo

        if args.scenario is None:
            args.scenario = demo.DEMO_SCENARIO
        return demo.main(args)
    if args.command == "sim":
        return _cmd_sim(args)
    if args.command == "replay":
        return _cmd_replay(args)
    if args.command == "detect":
        from app import detect_images

        _keep_inputs(args, args.images)
        return detect_images.main(args)
    if args.command in ("run", "service"):
        from app.supervisor import service

        return service.main(args)
    if args.command == "status":
        return _cmd_status(args)
    if args.command == "install-service":
        from app.supervisor import install

        return install.main(args)
    if args.command == "bench":
        from app import bench

        return bench.main(args)
    if args.command == "fleet":
        from app.fleet import run

        return run.main(args)
    if args.command == "config":
        return _cmd_config(args)
    if args.command == "train":
        return _cmd_train(args)
    if args.command == "calibrate":
        from app import calibrate

        _keep_inputs(args, args.images)
        return calibrate.main(args)
    if args.command == "eval":
        from app.eval import report

        return report.main(args)
    raise AssertionError(args.command)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "config":
        # a check opens models and sources: OpenCV's own log lines would come before (and say less than) ours
        os.environ["OPENCV_LOG_LEVEL"] = "SILENT"
    from app.config import ConfigFileError, error_line
    from app.core import ConfigError, CoreError

    try:
        return _dispatch(args)
    except (ConfigFileError, ConfigError) as exc:
        # one mapping: every configuration error is exit 2, one line, its file, the key's line, the key
        print(f"headway: configuration error: {error_line(exc, getattr(args, 'config', None) or getattr(args, 'file', None))}",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except (CoreError, OSError, RuntimeError, ValueError) as exc:
        # every expected failure (bad source, scenario, image, ...) as one line
        print(f"headway: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
