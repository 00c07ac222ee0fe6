#!/usr/bin/env python3
"""Time the reference implementations on the workloads `dggt bench compute` times.

Two references:

* the DGGT release's network (``--release-src DIR``, the repository root holding ``dggt/``), built with random
  weights (timing only; no checkpoint is ever loaded);
* gsplat's ``rasterization`` (``--gsplat``).

Workloads (each: ``--warmup`` untimed runs, then ``--repeat`` timed runs; the median is reported):

* ``forward/{S}/{f32,bf16}``       the release forward on ``[1, S, 3, 350, 518]`` under ``no_grad``;
* ``train-step/{N}+{2N}/f32``       one fine-tuning step: forward on N frames, 2N target views rendered with gsplat
                                    from the per-pixel Gaussians, L1 loss, backward, AdamW step, ``zero_grad``;
* ``raster/{G}x{V}/forward``       gsplat rasterisation of G Gaussians into V views of 518x350;
* ``raster/{G}x{V}/forward+backward``  the same plus ``colors.sum().backward()``;
* ``longest/{precision}``          the largest S whose forward fits in GPU memory (doubling, then bisection).

The JSON written to ``--out`` (after every workload, so a killed run keeps what finished) is read by the Rust side
to print ratios. A markdown table of the records goes to stdout at the end; progress goes to stderr.

Example (on a CUDA machine):

    python3 scripts/reference_bench.py --out reference.json --release-src /path/to/dggt-release --gsplat

Smoke test on a CPU (gsplat workloads then record an error, since gsplat needs CUDA):

    python3 scripts/reference_bench.py --out /tmp/ref.json --release-src /path/to/dggt-release \
        --device cpu --reduced
"""

import argparse
import gc
import importlib
import json
import math
import os
import statistics
import sys
import time
import traceback
import types

# ----------------------------------------------------------------------------------------------------------------
# Sizes

FULL = dict(height=350, width=518, forward_frames=[4, 12], train_frames=4, raster_gaussians=2_200_000,
            raster_views=12, longest_start=16, longest_max=None)
REDUCED = dict(height=56, width=70, forward_frames=[2], train_frames=2, raster_gaussians=2000, raster_views=2,
               longest_start=16, longest_max=8)

# Focal length of the raster scene at 518 px wide; scaled with the width for reduced sizes.
RASTER_FOCAL_518 = 300.0
LONGEST_TOLERANCE = 4

WORKLOADS = ["forward", "train-step", "raster", "longest"]


def log(msg):
    print(f"[reference_bench {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def mib(nbytes):
    return round(nbytes / (1024.0 * 1024.0), 1)


# ----------------------------------------------------------------------------------------------------------------
# Stand-in modules for imports the release makes but the benchmark never exercises


def _stand_in_module(name, attrs=None, doc=""):
    """A module whose listed attributes exist and whose every other attribute raises a clear error on use."""
    module = types.ModuleType(name)
    module.__doc__ = f"reference_bench stand-in for {name}. {doc}"
    module.__reference_bench_stand_in__ = True
    for key, value in (attrs or {}).items():
        setattr(module, key, value)

    def __getattr__(attr):  # module-level __getattr__ (PEP 562)
        if attr.startswith("__"):
            raise AttributeError(attr)
        raise AttributeError(f"{name}.{attr} is not available: {name} is a stand-in inserted by reference_bench.py")

    module.__getattr__ = __getattr__
    return module


class _NearestNeighbors:
    """Stand-in for sklearn.neighbors.NearestNeighbors (brute force with torch), used by the release's sky model
    to size its background Gaussians at construction."""

    def __init__(self, n_neighbors=5, algorithm="auto", metric="euclidean", **_kwargs):
        if metric != "euclidean":
            raise ValueError("the NearestNeighbors stand-in supports only the euclidean metric")
        self.n_neighbors = n_neighbors
        self._points = None

    def fit(self, points):
        import numpy as np

        self._points = np.ascontiguousarray(points, dtype=np.float32)
        return self

    def kneighbors(self, queries=None, n_neighbors=None, return_distance=True):
        import numpy as np
        import torch

        k = n_neighbors or self.n_neighbors
        device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
        ref = torch.from_numpy(self._points).to(device)
        q = ref if queries is None else torch.from_numpy(np.ascontiguousarray(queries, dtype=np.float32)).to(device)
        chunk = 4096 if device.type == "cuda" else 512
        dists, idxs = [], []
        for part in q.split(chunk):
            d2 = (part * part).sum(1, keepdim=True) - 2.0 * part @ ref.T + (ref * ref).sum(1)[None]
            best, index = d2.topk(k, dim=1, largest=False)
            dists.append(best.clamp_min(0).sqrt().cpu())
            idxs.append(index.cpu())
        dist = torch.cat(dists).numpy().astype(np.float64)
        index = torch.cat(idxs).numpy().astype(np.int64)
        return (dist, index) if return_distance else index


class Unavailable(RuntimeError):
    """A workload cannot run here (recorded as its error without a traceback)."""


def _gsplat_missing_rasterization(*_args, **_kwargs):
    raise Unavailable("gsplat is not importable here (a stand-in was inserted so the release could import)")


def _try_import(name):
    try:
        importlib.import_module(name)
        return None
    except Exception as exc:  # noqa: BLE001 - any failure to import means a stand-in is needed
        return f"{type(exc).__name__}: {exc}"


def install_stand_ins():
    """Make the release importable: real modules where they import, stand-ins otherwise. Returns what was stood in."""
    used = []

    def need(name, build):
        problem = _try_import(name)
        if problem is None:
            return
        for mod_name, module in build().items():
            sys.modules[mod_name] = module
        used.append(name)
        log(f"stand-in for {name} ({problem})")

    # The release imports IPython only for `embed`, a debugging hook it never calls on the benchmarked paths.
    need("IPython", lambda: {"IPython": _stand_in_module("IPython", {"embed": lambda *a, **k: None})})
    # open3d: imported at the top of dggt/models/sky.py and dggt/utils/gs.py, used only in commented-out code.
    need("open3d", lambda: {"open3d": _stand_in_module("open3d")})
    # sklearn: the sky model's constructor sizes its background Gaussians by nearest-neighbour distances.
    need("sklearn", lambda: {
        "sklearn": _stand_in_module("sklearn"),
        "sklearn.neighbors": _stand_in_module("sklearn.neighbors", {"NearestNeighbors": _NearestNeighbors}),
    })
    # Plotting and image I/O: imported by dggt/models/projector.py, unused by the sky model's projection.
    need("matplotlib.pyplot", lambda: {
        "matplotlib": _stand_in_module("matplotlib"),
        "matplotlib.pyplot": _stand_in_module("matplotlib.pyplot"),
    })
    need("PIL.ImageDraw", lambda: {
        "PIL": _stand_in_module("PIL"),
        "PIL.Image": _stand_in_module("PIL.Image"),
        "PIL.ImageDraw": _stand_in_module("PIL.ImageDraw"),
    })
    # einops: only the track head (never run: no query points) uses it.
    need("einops", lambda: {"einops": _stand_in_module("einops")})
    # huggingface_hub: the mixin only adds from_pretrained/save_pretrained.
    need("huggingface_hub", lambda: {
        "huggingface_hub": _stand_in_module("huggingface_hub", {"PyTorchModelHubMixin": type("PyTorchModelHubMixin",
                                                                                            (), {})}),
    })
    # gsplat: sky.py imports gsplat.rendering.rasterization at module level.
    need("gsplat.rendering", lambda: {
        "gsplat": _stand_in_module("gsplat"),
        "gsplat.rendering": _stand_in_module("gsplat.rendering", {"rasterization": _gsplat_missing_rasterization}),
    })
    return used


# ----------------------------------------------------------------------------------------------------------------
# The run's shared state


class Bench:
    def __init__(self, args):
        import torch

        self.args = args
        self.torch = torch
        self.device = torch.device(args.device)
        self.is_cuda = self.device.type == "cuda"
        self.sizes = dict(REDUCED if args.reduced else FULL)
        self.records = []
        self.release_src = os.path.abspath(args.release_src) if args.release_src else None
        self.stand_ins = []
        self.VGGT = None
        self.model = None
        self.model_build_s = None
        self.gsplat = None  # the module, once imported
        self.gsplat_version = None
        self.gsplat_error = None
        self.rasterization = None
        self.gsplat_warmup_s = None
        if self.is_cuda:
            self.device_name = torch.cuda.get_device_name(self.device)
        else:
            self.device_name = self.device.type
        if args.tf32:
            torch.backends.cuda.matmul.allow_tf32 = True
            torch.backends.cudnn.allow_tf32 = True

    # -- output ---------------------------------------------------------------------------------------------------

    def document(self):
        return {
            "implementation": "reference",
            "torch": self.torch.__version__,
            "device": self.device_name,
            "gsplat": self.gsplat_version,
            "release_src": self.release_src,
            "records": self.records,
        }

    def write(self):
        path = self.args.out
        tmp = f"{path}.tmp{os.getpid()}"
        with open(tmp, "w") as f:
            json.dump(self.document(), f, indent=1)
            f.write("\n")
        os.replace(tmp, path)

    def add(self, record):
        self.records.append(record)
        self.write()
        if "error" in record:
            log(f"{record['key']}: error: {record['error']}")
        elif "frames" in record:
            log(f"{record['key']}: {record['frames']} frames")
        else:
            log(f"{record['key']}: median {record['median_ms']:.2f} ms, peak {record['peak_mib']} MiB")

    # -- device helpers -------------------------------------------------------------------------------------------

    def sync(self):
        if self.is_cuda:
            self.torch.cuda.synchronize(self.device)

    def release_memory(self):
        gc.collect()
        if self.is_cuda:
            self.torch.cuda.empty_cache()

    def start_peak(self):
        self.release_memory()
        if self.is_cuda:
            self.torch.cuda.reset_peak_memory_stats(self.device)

    def peak_mib(self):
        if not self.is_cuda:
            return None
        return mib(self.torch.cuda.max_memory_reserved(self.device))

    def autocast(self, precision):
        """The release's own mixed precision: autocast around `model(images)` (inference.py)."""
        torch = self.torch
        if precision == "f32":
            return torch.autocast(device_type=self.device.type, enabled=False)
        if precision == "bf16":
            return torch.autocast(device_type=self.device.type, dtype=torch.bfloat16)
        raise ValueError(f"unknown precision {precision}")

    def timed(self, fn):
        """`warmup` untimed runs, then `repeat` timed ones; the clock stops after a device synchronise."""
        for _ in range(self.args.warmup):
            fn()
            self.sync()
        runs = []
        for _ in range(self.args.repeat):
            self.sync()
            t0 = time.perf_counter()
            fn()
            self.sync()
            runs.append((time.perf_counter() - t0) * 1e3)
        return runs

    def timing_record(self, key, impl, runs, note):
        return {"key": key, "impl": impl, "median_ms": round(statistics.median(runs), 3),
                "runs_ms": [round(r, 3) for r in runs], "peak_mib": self.peak_mib(), "note": note}

    # -- the release ----------------------------------------------------------------------------------------------

    def import_release(self):
        if self.VGGT is not None:
            return
        torch = self.torch
        if not os.path.isdir(os.path.join(self.release_src, "dggt")):
            raise RuntimeError(f"--release-src {self.release_src} has no dggt/ package")
        self.stand_ins = install_stand_ins()
        # inference.py and the heads use torch.cuda.amp.autocast, deprecated in recent PyTorch.
        if not hasattr(torch.cuda, "amp") or not hasattr(torch.cuda.amp, "autocast"):
            import functools

            torch.cuda.amp.autocast = functools.partial(torch.autocast, "cuda")
            self.stand_ins.append("torch.cuda.amp.autocast")
        import warnings

        warnings.filterwarnings("ignore", category=FutureWarning, message=r".*torch\.cuda\.amp\.autocast.*")
        if self.release_src not in sys.path:
            sys.path.insert(0, self.release_src)
        t0 = time.perf_counter()
        from dggt.models.vggt import VGGT

        self.VGGT = VGGT
        log(f"imported the release's VGGT from {self.release_src} in {time.perf_counter() - t0:.1f} s"
            + (f" (stand-ins: {', '.join(self.stand_ins)})" if self.stand_ins else ""))

    def get_model(self):
        if self.model is not None:
            return self.model
        self.import_release()
        torch = self.torch
        torch.manual_seed(self.args.seed)
        log("building the release network with random weights (img_size=518) ...")
        t0 = time.perf_counter()
        model = None
        if self.is_cuda:
            # Initialising ~1.35 G parameters is much faster on the GPU. The constructor's few legacy CPU tensors
            # (normalisation constants, sky-model buffers) are moved by the .to() below.
            try:
                with torch.device(self.device):
                    model = self.VGGT()
            except Exception as exc:  # noqa: BLE001
                log(f"building on {self.device} failed ({type(exc).__name__}: {exc}); building on the CPU")
                model = None
                self.release_memory()
        if model is None:
            model = self.VGGT()
        model = model.to(self.device).eval()
        model.requires_grad_(False)
        self.sync()
        self.model_build_s = time.perf_counter() - t0
        n_params = sum(p.numel() for p in model.parameters())
        log(f"built in {self.model_build_s:.1f} s: {n_params / 1e6:.1f} M parameters")
        self.model = model
        return model

    def release_note(self):
        extra = f"; stand-in modules: {', '.join(self.stand_ins)}" if self.stand_ins else ""
        return f"DGGT release VGGT from {self.release_src}, random init{extra}"

    def images(self, frames, seed_offset=0):
        torch = self.torch
        g = torch.Generator().manual_seed(self.args.seed + seed_offset)
        h, w = self.sizes["height"], self.sizes["width"]
        return torch.rand((1, frames, 3, h, w), generator=g).to(self.device)

    # -- gsplat ---------------------------------------------------------------------------------------------------

    def get_gsplat(self):
        """gsplat's rasterization, after one untimed warm-up call (the JIT compile). Raises if unusable here."""
        if self.rasterization is not None:
            return self.rasterization
        if self.gsplat_error is not None:
            raise Unavailable(self.gsplat_error)
        try:
            if not self.is_cuda:
                raise Unavailable(f"gsplat needs CUDA; the device is {self.device.type}")
            import gsplat
            from gsplat.rendering import rasterization

            if getattr(gsplat, "__reference_bench_stand_in__", False):
                raise Unavailable("gsplat is not installed (only a stand-in module was importable)")
            self.gsplat = gsplat
            self.gsplat_version = getattr(gsplat, "__version__", "unknown")
            log(f"gsplat {self.gsplat_version}: warm-up call (may JIT-compile its CUDA code, minutes) ...")
            torch = self.torch
            t0 = time.perf_counter()
            g = torch.Generator().manual_seed(1)
            n = 4096
            means = (torch.rand((n, 3), generator=g) - 0.5) * 2
            means[:, 2] += 5.0
            params = [means,
                      torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(n, 1),
                      torch.full((n, 3), 0.05),
                      torch.full((n,), 0.5),
                      torch.rand((n, 3), generator=g)]
            params = [p.to(self.device).requires_grad_(True) for p in params]
            viewmats = torch.eye(4).unsqueeze(0).to(self.device)
            ks = torch.tensor([[[64.0, 0.0, 32.0], [0.0, 64.0, 32.0], [0.0, 0.0, 1.0]]]).to(self.device)
            for packed in (True, False):
                colors, alphas, _ = rasterization(*params, viewmats, ks, 64, 64, packed=packed)
                (colors.sum() + alphas.sum()).backward()
            self.sync()
            self.gsplat_warmup_s = time.perf_counter() - t0
            log(f"gsplat warm-up took {self.gsplat_warmup_s:.1f} s")
            self.rasterization = rasterization
            return rasterization
        except Exception as exc:  # noqa: BLE001 - recorded on every gsplat workload
            self.gsplat_error = str(exc) if isinstance(exc, Unavailable) else f"{type(exc).__name__}: {exc}"
            raise

    # -- workloads ------------------------------------------------------------------------------------------------

    def run_workload(self, key, impl, fn):
        """Run one workload; a failure records an error and the run goes on."""
        log(f"{key}: start")
        try:
            record = fn()
        except Exception as exc:  # noqa: BLE001
            quiet = isinstance(exc, (Unavailable, self.torch.cuda.OutOfMemoryError))
            message = str(exc) if isinstance(exc, Unavailable) else f"{type(exc).__name__}: {exc}"
            message = message.strip()
            if len(message) > 600:
                message = message[:600] + " ..."
            if not quiet:
                traceback.print_exc(file=sys.stderr)
            record = {"key": key, "impl": impl, "error": message}
        self.release_memory()
        self.add(record)

    def forward_once(self, model, images, precision):
        with self.torch.no_grad(), self.autocast(precision):
            out = model(images)
        del out

    def workload_forward(self, frames, precision):
        key = f"forward/{frames}/{precision}"

        def fn():
            model = self.get_model()
            self.start_peak()
            images = self.images(frames)
            runs = self.timed(lambda: self.forward_once(model, images, precision))
            h, w = self.sizes["height"], self.sizes["width"]
            note = (f"{self.release_note()}; model(images) on [1,{frames},3,{h},{w}] in [0,1] under no_grad, "
                    "all heads the forward runs (camera, point, gs, instance, semantic, depth; no track head: no "
                    "query points)")
            if precision == "bf16":
                note += ("; bf16 as the release runs it: autocast(bfloat16) around model(images), so only the "
                         "aggregator runs in bf16: the heads disable autocast inside forward and run in f32")
            else:
                note += "; f32, no autocast"
            note += f"; TF32 matmul {'on' if self.args.tf32 else 'off (PyTorch default)'}"
            return self.timing_record(key, "release", runs, note)

        self.run_workload(key, "release", fn)

    def workload_train_step(self):
        n = self.sizes["train_frames"]
        key = f"train-step/{n}+{2 * n}/f32"
        self.run_workload(key, "release+gsplat", lambda: self.train_step(n, key))

    def train_step(self, n, key):
        torch = self.torch
        rasterization = self.get_gsplat()
        model = self.get_model()
        frozen = ("aggregator", "camera_head", "depth_head")
        trained = [name for name, _ in model.named_children() if name not in frozen]
        optimizer = None
        try:
            model.train()
            for name, child in model.named_children():
                child.requires_grad_(name not in frozen)
            sky = [p for p in model.sky_model.parameters() if p.requires_grad]
            sky_ids = {id(p) for p in sky}
            rest = [p for name in trained if name != "sky_model"
                    for p in getattr(model, name).parameters() if id(p) not in sky_ids]
            groups = [{"params": rest, "lr": 4e-5}]
            if sky:
                groups.append({"params": sky, "lr": 1e-4})
            optimizer = torch.optim.AdamW(groups, lr=4e-5, weight_decay=1e-4)

            self.start_peak()
            h, w = self.sizes["height"], self.sizes["width"]
            dev = self.device
            images = self.images(n)
            g = torch.Generator().manual_seed(self.args.seed + 7)
            targets = torch.rand((2 * n, h, w, 3), generator=g).to(dev)

            # Cameras: identity rotations, moving forward along +z; the targets span the inputs' path.
            focal = RASTER_FOCAL_518 * w / 518.0
            k = torch.tensor([[focal, 0.0, w / 2.0], [0.0, focal, h / 2.0], [0.0, 0.0, 1.0]])
            step = 0.5

            def cams(count, span):
                pos = torch.linspace(0.0, span, count) if count > 1 else torch.zeros(1)
                view = torch.eye(4).repeat(count, 1, 1)
                view[:, 2, 3] = -pos  # world-to-camera translation
                return pos, view.to(dev), k.repeat(count, 1, 1).to(dev)

            src_pos, src_view, src_k = cams(n, step * (n - 1))
            tgt_pos, tgt_view, tgt_k = cams(2 * n, step * (n - 1))
            src_t = torch.linspace(0.0, 1.0, n).to(dev) if n > 1 else torch.zeros(1, device=dev)
            tgt_t = torch.linspace(0.0, 1.0, 2 * n).to(dev)
            ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32),
                                    indexing="ij")
            rays = torch.stack([(xs - w / 2.0) / focal, (ys - h / 2.0) / focal, torch.ones_like(xs)], -1).to(dev)
            offsets = torch.zeros((n, 1, 1, 3), device=dev)
            offsets[:, 0, 0, 2] = src_pos.to(dev)
            frame_t = src_t[:, None, None].expand(n, h, w).reshape(-1)
            log_gamma1 = math.log(0.1)

            def one_step():
                preds = model(images)
                depth = preds["depth"][0, ..., 0]  # [N, H, W], frozen head: no graph
                gs = preds["gs_map"][0]  # [N, H, W, 11]: rgb, opacity, scale, rotation
                lifespan = preds["gs_conf"][0].reshape(-1)  # [N*H*W]
                dynamic = preds["dynamic_conf"][0, ..., 0].reshape(-1)
                means = (rays[None] * depth[..., None] + offsets).reshape(-1, 3)
                rgb = gs[..., 0:3].reshape(-1, 3)
                opacity = gs[..., 3].reshape(-1) * (1.0 - torch.sigmoid(dynamic))
                scales = gs[..., 4:7].reshape(-1, 3)
                quats = gs[..., 7:11].reshape(-1, 4)
                sigma = log_gamma1 / (lifespan * lifespan + 1e-6)
                renders, alphas = [], []
                for j in range(2 * n):
                    faded = opacity * torch.exp(sigma * (tgt_t[j] - frame_t) ** 2)
                    color, alpha, _ = rasterization(means, quats, scales, faded, rgb, tgt_view[j:j + 1],
                                                    tgt_k[j:j + 1], w, h)
                    renders.append(color)
                    alphas.append(alpha)
                render = torch.cat(renders, 0)
                alpha = torch.cat(alphas, 0)
                background = model.sky_model.forward_with_new_pose(images, src_view, src_k, tgt_view, tgt_k)
                composite = alpha * render + (1.0 - alpha) * background
                loss = (composite - targets).abs().mean()
                loss.backward()
                optimizer.step()
                optimizer.zero_grad(set_to_none=True)
                return means.shape[0]

            gaussians = []
            runs = self.timed(lambda: gaussians.append(one_step()))
            n_trained = sum(p.numel() for grp in groups for p in grp["params"])
            note = (f"{self.release_note()}; one fine-tuning step written here after the release's train.py (its "
                    "loop is not callable: DDP, dataset, LPIPS): model.train(), aggregator/camera_head/depth_head "
                    f"frozen, {', '.join(trained)} trainable ({n_trained / 1e6:.1f} M params; the point, semantic "
                    "and track heads get no gradient: not in the loss), AdamW weight decay 1e-4, lr 4e-5 and "
                    "1e-4 for sky_model as the release; forward on "
                    f"[1,{n},3,{h},{w}] f32 (no autocast); {gaussians[-1]} Gaussians (every pixel of every input: "
                    "gs_head rgb/opacity/scale/rotation, opacity x (1 - sigmoid(instance_head)), means = depth_head "
                    f"depth unprojected with fixed pinhole cameras f={focal:.1f}, identity rotations, 0.5 m apart); "
                    f"{2 * n} target views {w}x{h}, each a gsplat rasterization call (gsplat defaults, packed=True, "
                    "as the release) with the release's lifespan fade of opacity at the target time, composited "
                    "over the sky model's render (forward_with_new_pose); loss = L1 against random targets "
                    "(no LPIPS, sky-mask, lifespan or dynamic terms); backward, optimizer.step(), "
                    "zero_grad(set_to_none=True)")
            return self.timing_record(key, "release+gsplat", runs, note)
        finally:
            if optimizer is not None:
                optimizer.state.clear()
            del optimizer
            model.zero_grad(set_to_none=True)
            model.requires_grad_(False)
            model.eval()
            self.release_memory()

    def raster_scene(self, count, views, requires_grad):
        """Gaussians spread in front of the cameras like the pixel-aligned Gaussians of driving frames."""
        torch = self.torch
        h, w = self.sizes["height"], self.sizes["width"]
        fx = fy = RASTER_FOCAL_518 * w / 518.0
        cx, cy = w / 2.0, h / 2.0
        g = torch.Generator().manual_seed(self.args.seed + 1234)

        def r(*shape):
            return torch.rand(shape, generator=g)

        u, v = r(count) * w, r(count) * h
        depth = 2.0 + 58.0 * r(count) * r(count)
        means = torch.stack([(u - cx) / fx * depth, (v - cy) / fy * depth, depth], -1)
        quats = torch.stack([torch.ones(count), 0.2 * r(count), 0.2 * r(count), 0.2 * r(count)], -1)
        s = (0.5 + 1.5 * r(count)) * depth / fx
        scales = torch.stack([s, s * (0.5 + r(count)), 0.3 * s], -1)
        opacities = 0.3 + 0.65 * r(count)
        colors = r(count, 3)
        viewmats = torch.eye(4).repeat(views, 1, 1)
        viewmats[:, 2, 3] = -torch.arange(views, dtype=torch.float32) * 1.5 / 12.0
        ks = torch.tensor([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]).repeat(views, 1, 1)
        params = [t.to(self.device).requires_grad_(requires_grad) for t in (means, quats, scales, opacities, colors)]
        return params, viewmats.to(self.device), ks.to(self.device)

    def workload_raster(self, backward):
        count, views = self.sizes["raster_gaussians"], self.sizes["raster_views"]
        what = "forward+backward" if backward else "forward"
        key = f"raster/{count}x{views}/{what}"

        def fn():
            torch = self.torch
            rasterization = self.get_gsplat()
            self.start_peak()
            h, w = self.sizes["height"], self.sizes["width"]
            params, viewmats, ks = self.raster_scene(count, views, backward)

            def once():
                if backward:
                    for p in params:
                        p.grad = None
                    colors, _, _ = rasterization(*params, viewmats, ks, w, h, packed=False)
                    colors.sum().backward()
                else:
                    with torch.no_grad():
                        colors, _, _ = rasterization(*params, viewmats, ks, w, h, packed=False)
                del colors

            runs = self.timed(once)
            note = (f"gsplat {self.gsplat_version} rasterization, {count} Gaussians into {views} views {w}x{h}, "
                    "render_mode RGB, packed=False, otherwise gsplat defaults (classic, eps2d 0.3, near 0.01, "
                    "sh_degree None: colours post-activation); scene: pixel-aligned-like Gaussians at depth "
                    "2 + 58 r1 r2, f=300 (x w/518), views along z every 0.125 m; ")
            note += ("loss = colors.sum(), backward to means, quats, scales, opacities, colors (grads set to None "
                     "before each run)" if backward else "forward only, under no_grad")
            if self.gsplat_warmup_s is not None:
                note += f"; first (untimed) gsplat call incl. JIT compile/load took {self.gsplat_warmup_s:.1f} s"
            return self.timing_record(key, "gsplat", runs, note)

        self.run_workload(key, "gsplat", fn)

    def workload_longest(self, precision):
        key = f"longest/{precision}"

        def fn():
            torch = self.torch
            model = self.get_model()
            cap = self.args.longest_max
            if self.sizes["longest_max"] is not None:
                cap = min(cap, self.sizes["longest_max"])
            start = min(self.sizes["longest_start"], cap)
            peaks = {}

            def trial(frames):
                self.start_peak()
                t0 = time.perf_counter()
                fits = False
                try:
                    images = self.images(frames)
                    self.forward_once(model, images, precision)
                    self.sync()
                    fits = True
                except torch.cuda.OutOfMemoryError:
                    pass
                images = None
                seconds = time.perf_counter() - t0
                peak = self.peak_mib()
                self.release_memory()
                peaks[frames] = peak
                log(f"{key}: S={frames}: {'fits' if fits else 'out of memory'} ({seconds:.1f} s"
                    + (f", peak {peak} MiB" if peak is not None else "") + ")")
                return fits

            best, why = search_longest(trial, start, cap, LONGEST_TOLERANCE, self.args.longest_budget_s)
            h, w = self.sizes["height"], self.sizes["width"]
            note = (f"{self.release_note()}; largest S whose forward on [1,S,3,{h},{w}] under no_grad"
                    f" ({'autocast bf16 around model(images), heads in f32' if precision == 'bf16' else 'f32'})"
                    f" completes without CUDA out-of-memory; doubling from {start}, then bisection to within "
                    f"{LONGEST_TOLERANCE} frames; {why}")
            if best and peaks.get(best) is not None:
                note += f"; peak reserved at S={best}: {peaks[best]} MiB"
            return {"key": key, "impl": "release", "frames": best, "note": note}

        self.run_workload(key, "release", fn)


def search_longest(trial, start, cap, tolerance, budget_s, clock=time.perf_counter):
    """The largest S in [1, cap] for which `trial(S)` is true, assuming fits are monotone: doubling from `start`,
    then bisection until the bracket is within `tolerance`. Stops when `budget_s` of wall clock has passed.

    Returns (best S or 0, a sentence saying how the search ended)."""
    t0 = clock()
    lo, hi = 0, None  # lo fits (0: nothing known to fit), hi does not fit (None: no failure seen)
    trials = 0

    def out_of_time():
        return clock() - t0 >= budget_s

    s = max(1, min(start, cap))
    while True:
        if out_of_time():
            return lo, (f"wall-clock budget of {budget_s:g} s ran out while doubling after {trials} trials: "
                        f"best so far, a lower bound")
        trials += 1
        if trial(s):
            lo = s
            if s >= cap:
                return lo, f"reached the cap --longest-max {cap} after {trials} trials (a lower bound)"
            s = min(2 * s, cap)
        else:
            hi = s
            break
    while hi - lo > tolerance:
        if out_of_time():
            return lo, (f"wall-clock budget of {budget_s:g} s ran out while bisecting between {lo} (fits) and "
                        f"{hi} (out of memory) after {trials} trials: best so far")
        mid = (lo + hi) // 2
        trials += 1
        if trial(mid):
            lo = mid
        else:
            hi = mid
    return lo, f"{lo} fits and {hi} runs out of memory ({trials} trials)"


# ----------------------------------------------------------------------------------------------------------------


def markdown_table(records):
    lines = ["| key | impl | median ms | peak MiB | frames | note |", "| --- | --- | ---: | ---: | ---: | --- |"]
    for r in records:
        note = r.get("error")
        note = f"ERROR: {note}" if note else r.get("note", "")
        note = note.replace("|", "/").replace("\n", " ")
        if len(note) > 160:
            note = note[:157] + "..."
        median = f"{r['median_ms']:.2f}" if "median_ms" in r else ""
        peak = f"{r['peak_mib']:.0f}" if r.get("peak_mib") is not None else ""
        frames = str(r["frames"]) if "frames" in r else ""
        lines.append(f"| {r['key']} | {r['impl']} | {median} | {peak} | {frames} | {note} |")
    return "\n".join(lines)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="the JSON file to write")
    p.add_argument("--release-src", help="root of the DGGT release source tree (holds dggt/); without it the "
                                         "release workloads are skipped")
    p.add_argument("--gsplat", action="store_true", help="run the gsplat workloads (raster; train-step with "
                                                        "--release-src)")
    p.add_argument("--workloads", default=",".join(WORKLOADS),
                   help=f"comma-separated subset of {','.join(WORKLOADS)} (default: all)")
    p.add_argument("--repeat", type=int, default=5, help="timed runs per workload (default 5)")
    p.add_argument("--warmup", type=int, default=1, help="untimed runs before the timed ones (default 1)")
    p.add_argument("--device", default="cuda", help="torch device (default cuda)")
    p.add_argument("--reduced", action="store_true",
                   help="smoke-test sizes: 70x56 images, S=2, 2000 Gaussians x 2 views, longest capped at 8")
    p.add_argument("--longest-precisions", default="bf16", help="comma-separated from bf16,f32 (default bf16)")
    p.add_argument("--longest-max", type=int, default=512, help="cap on the longest search (default 512)")
    p.add_argument("--longest-budget-s", type=float, default=240.0,
                   help="wall-clock budget of each longest search in seconds (default 240)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tf32", action="store_true", help="allow TF32 matmuls/convolutions (default: PyTorch's "
                                                      "defaults, TF32 matmul off)")
    args = p.parse_args(argv)
    args.workloads = [w.strip() for w in args.workloads.split(",") if w.strip()]
    unknown = [w for w in args.workloads if w not in WORKLOADS]
    if unknown:
        p.error(f"unknown workloads {unknown}; choose from {WORKLOADS}")
    args.longest_precisions = [x.strip() for x in args.longest_precisions.split(",") if x.strip()]
    bad = [x for x in args.longest_precisions if x not in ("bf16", "f32")]
    if bad:
        p.error(f"unknown --longest-precisions {bad}")
    if args.repeat < 1 or args.warmup < 0:
        p.error("--repeat must be at least 1 and --warmup at least 0")
    return args


def main(argv=None):
    args = parse_args(argv)
    import torch

    if args.device.startswith("cuda") and not torch.cuda.is_available():
        log("CUDA is not available: pass --device cpu (with --reduced) for a smoke test")
        return 2
    bench = Bench(args)
    log(f"torch {torch.__version__} on {bench.device_name}; "
        f"{'reduced' if args.reduced else 'full'} sizes; workloads {','.join(args.workloads)}")
    bench.write()
    sizes = bench.sizes
    release = bench.release_src is not None
    wanted = set(args.workloads)

    if "raster" in wanted:
        if args.gsplat:
            # First, before the network occupies memory, so the peak is gsplat's own.
            bench.workload_raster(backward=False)
            bench.workload_raster(backward=True)
        else:
            log("raster: skipped (no --gsplat)")
    if "forward" in wanted:
        if release:
            for frames in sizes["forward_frames"]:
                for precision in ("f32", "bf16"):
                    bench.workload_forward(frames, precision)
        else:
            log("forward: skipped (no --release-src)")
    if "train-step" in wanted:
        if release and args.gsplat:
            bench.workload_train_step()
        else:
            log("train-step: skipped (needs --release-src and --gsplat)")
    if "longest" in wanted:
        if release:
            for precision in args.longest_precisions:
                bench.workload_longest(precision)
        else:
            log("longest: skipped (no --release-src)")

    bench.write()
    log(f"wrote {args.out} ({len(bench.records)} records)")
    print(markdown_table(bench.records), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
