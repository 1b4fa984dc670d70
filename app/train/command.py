"""`headway train cascade | proposals | verifier`: the options of each trainer, read into the trainer's
own parameters, and its run. The trainers themselves (app/train/cascade/, proposals.py, verifier*.py)
know nothing of the command line."""
from __future__ import annotations

import contextlib
from typing import Callable, Iterator

from app import config as configuration
from app.eval.tusimple_boxes import tusimple_config
from app.output_files import check_outputs, numbered, written_whole
from app.train import proposals, verifier, verifier_cnn
from app.train.cascade import TrainParams, train


class OptionError(RuntimeError):
    """An option's text that does not read as its value; the message names the option and gives an example.
    Not a ValueError, which argparse would replace by its own usage line and exit 2: this one reaches the
    CLI's one-line error (exit 1), as every other bad value of a command does."""


def window_size(text: str) -> tuple[int, int]:
    """`--window WIDTHxHEIGHT` in pixels."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise OptionError(f"--window {text!r}: give WIDTHxHEIGHT in pixels, e.g. 30x20") from None
    if min(w, h) < 6:
        raise OptionError(f"--window {text}: at least 6 px each way (OpenCV ignores a 1-px border)")
    return w, h


def scan_band(text: str) -> tuple:
    """`--scan-band ROW,HEIGHT_M[,MIN_M,MAX_M]` as the trainer's tuple."""
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) not in (2, 4) or v[1] <= 0 or (len(v) == 4 and not 0 < v[2] < v[3]):
        raise OptionError(f"--scan-band {text!r}: give ROW,HEIGHT_M or ROW,HEIGHT_M,MIN_M,MAX_M (horizon row in px, "
                          f"camera height in m, the lowest and tallest vehicle in m, lowest first), e.g. 344,1.8")
    return v


def conv_channels(text: str) -> tuple[int, int, int]:
    """`--channels A/B/C`: the widths of the CNN verifier's three conv layers."""
    try:
        channels = tuple(int(c) for c in text.split("/"))
    except ValueError:
        channels = ()
    if len(channels) != 3 or min(channels) < 1:
        raise OptionError(f"--channels {text!r}: give three conv widths, e.g. 8/16/32")
    return channels


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("train", help="train a learned model from annotated images")
    ts = s.add_subparsers(dest="model", required=True, metavar="MODEL")
    t = ts.add_parser("cascade", help="a Viola-Jones Haar cascade (OpenCV cascade XML) for vehicles")
    t.add_argument("--data", nargs="+", required=True,
                   help="folders with annotation.json in the TuSimple velocity format (every vehicle boxed)")
    t.add_argument("--out", required=True, help="cascade XML written after every stage")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--window", default="30x20", type=window_size, help="window WIDTHxHEIGHT, px (default 30x20)")
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
                        "Discrete AdaBoost as in paper 004, leaves +-alpha (docs/decisions.md compares them)")
    t.add_argument("--scan-band", metavar="ROW,HEIGHT_M[,MIN_M,MAX_M]", type=scan_band, default=(),
                   help="negatives only from the rows the cascade stage scans for each window size: the camera's "
                        "horizon row (px) and height (m), and the lowest and tallest vehicle (default 1.0,4.5 m); "
                        "TuSimple's camera: 344,1.8 (default: negatives from anywhere in the image)")
    t.add_argument("--log", help="also write the per-stage log here")
    t.set_defaults(run=run_cascade)
    t = ts.add_parser("proposals", help="the learned first stage: a small fully convolutional network giving the "
                      "vehicles' centres and boxes (ONNX for the detector part proposals; needs pip install '.[train]')")
    t.add_argument("--data", nargs="+", required=True, help="training folders (annotation.json, every vehicle boxed)")
    t.add_argument("--out", required=True, help="the network's ONNX, written after every epoch")
    t.add_argument("--epochs", type=int, default=30, help="passes over the fitted images (default 30, the shipped model's)")
    t.add_argument("--batch", type=int, default=16, help="images a batch (default 16)")
    t.add_argument("--lr", type=float, default=2e-3, help="Adam's first learning rate, falling linearly to 0 (default 2e-3)")
    t.add_argument("--input-width", type=int, default=320, help="px: the images reduced to this width (default 320)")
    t.add_argument("--subcells", type=int, choices=(1, 2), default=proposals.po.SUBCELLS,
                   help="sub-cells a side of each stride-8 cell: 2 = heat and boxes on a stride-4 grid (default "
                   f"{proposals.po.SUBCELLS}, the shipped model's); 1 = one a cell")
    t.add_argument("--limit", type=int, default=0, help="only the first N images (0 = all; for a quick check)")
    t.add_argument("--threads", type=int, default=2, help="CPU threads JAX may use (default 2)")
    t.add_argument("--cache", help=".npz keeping the reduced images between runs (made if absent; outside the repository)")
    t.add_argument("--log", help="also write the per-epoch log here")
    t.add_argument("--seed", type=int, default=0)
    t.set_defaults(run=run_proposals)
    t = ts.add_parser("verifier", help="a network judging the cascade's detections: a small CNN on the box's crop "
                      "(--out X.onnx, needs pip install '.[train]') or HOG + one hidden layer (--out X.yml[.gz])")
    t.add_argument("--data", nargs="+", required=True, help="training folders (annotation.json, as for the cascade)")
    t.add_argument("--cascade", required=True, help="the cascade XML whose detections are judged")
    t.add_argument("--out", required=True, help="verifier model: .onnx = the CNN, .yml or .yml.gz = HOG network")
    t.add_argument("--every", type=int, help="use every N-th image (default: 1 for the CNN, 4 for HOG)")
    t.add_argument("--hidden", type=int, default=64, help="hidden units (default 64)")
    t.add_argument("--epochs", type=int, help="passes over the samples (default: 6 for the CNN, 12 for HOG)")
    t.add_argument("--channels", default="8/16/32", type=conv_channels, help="CNN: widths of its three conv layers (default 8/16/32)")
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
                        "~2.4x faster (docs/detection.md)")
    t.add_argument("--decay", type=float, default=1e-4, help="L2 weight decay (default 1e-4)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--config", help="configuration YAML with the images' camera (default: the TuSimple camera)")
    t.set_defaults(run=run_verifier)


def _keep_inputs(args) -> None:
    """OutputPathError if an output names a training input (a folder, its annotations, the model resumed or
    judged, the configuration) or another output."""
    # the cache is read when present and written when absent: it may be neither an input nor another output
    check_outputs({"--out": args.out, "--log": getattr(args, "log", None), "--cache": getattr(args, "cache", None)},
                  {**numbered("--data folder", args.data),
                   **{f"--data folder {i + 1}'s annotation.json": f"{d}/annotation.json" for i, d in enumerate(args.data)},
                   **{opt: getattr(args, opt[2:], None) for opt in ("--resume", "--cascade", "--config")}})


def run_cascade(args) -> int:
    """The Viola-Jones trainer (app/train/cascade, independent of the rest of app)."""
    _keep_inputs(args)
    w, h = args.window
    p = TrainParams(width=w, height=h, stages=args.stages, num_pos=args.num_pos, num_neg=args.num_neg,
                    features=args.features, min_hit_rate=args.min_hit_rate, max_false_alarm=args.max_false_alarm,
                    seed=args.seed, max_minutes=args.max_minutes, resume=args.resume or "", booster=args.boost,
                    min_aspect=args.min_aspect, max_aspect=args.max_aspect, scan_band=args.scan_band)
    if not 0 <= p.min_aspect < p.max_aspect:
        raise ValueError(f"--min-aspect {p.min_aspect:g} --max-aspect {p.max_aspect:g}: give 0 <= min < max (box "
                         f"width / height)")
    with _line_logger(args.log) as log:
        train(args.data, args.out, p, log=log, written=written_whole)
    return 0


def run_proposals(args) -> int:
    """The learned first stage (detector part proposals)."""
    _keep_inputs(args)
    if args.epochs < 1 or args.batch < 1 or args.threads < 1 or args.input_width < 16:
        raise ValueError(f"--epochs {args.epochs} --batch {args.batch} --threads {args.threads} --input-width "
                         f"{args.input_width}: give at least 1 epoch, 1 image a batch, 1 thread and 16 px")
    with _line_logger(args.log) as log:
        proposals.train(args.data, args.out, epochs=args.epochs, seed=args.seed, input_width=args.input_width,
                        batch=args.batch, lr=args.lr, subcells=args.subcells, cache=args.cache, limit=args.limit, log=log,
                        threads=args.threads)
    return 0


def run_verifier(args) -> int:
    """The convolutional verifier run by cv::dnn in the core (--out X.onnx), or HOG + one hidden layer."""
    _keep_inputs(args)
    cfg = configuration.load(args.config) if args.config else tusimple_config(configuration.load(None))
    if args.out.endswith(".onnx"):
        with _line_logger(args.log) as log:
            verifier_cnn.train(args.data, args.cascade, args.out, cfg, every=args.every or 1, channels=args.channels,
                               hidden=args.hidden, epochs=args.epochs or 6, decay=args.decay, seed=args.seed,
                               cache=args.cache, compare_hog=args.compare_hog, log=log, box=not args.no_box,
                               near=args.near, margin=args.margin, neg_share=args.neg_share)
        return 0
    verifier.train(args.data, args.cascade, args.out, cfg, every=args.every or 4, hidden=args.hidden,
                   epochs=args.epochs or 12, decay=args.decay, seed=args.seed)
    return 0


@contextlib.contextmanager
def _line_logger(path: str | None) -> Iterator[Callable[[str], None]]:
    """A log that prints each training line and, with a path, also writes it to a file beside `path` that
    replaces it once the training completed (written_whole): a training that fails or is stopped leaves the
    previous log, its own lines are on stdout."""
    with written_whole(path) as tmp, (open(tmp, "w") if tmp else contextlib.nullcontext()) as fh:
        def log(line: str) -> None:
            print(line, flush=True)
            if fh:
                fh.write(line + "\n")
                fh.flush()   # the file beside `path` can be followed while a long training runs

        yield log
