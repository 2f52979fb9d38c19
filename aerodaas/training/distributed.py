"""``aerodaas train detector --workers N``: the same training loop as a Ray Train job on the Ray cluster the user
already has (``--address``, the ``aerodaas up`` cluster, or a local Ray).

Ray Train's ``TorchTrainer`` starts ``N`` worker actors (one CPU each, or one GPU each with ``--gpu``), joins them in
a PyTorch process group (gloo on CPUs, NCCL on GPUs) and wraps the module in ``DistributedDataParallel``
(``ray.train.torch.prepare_model``), which averages the gradients every step (Ray Train's "Get started with PyTorch"
guide). Each worker draws its own tiles (seed ``[seed, rank]``), so the job sees ``N`` times the tiles per step and
an epoch has ``tiles_per_epoch / (batch * N)`` steps. Rank 0 validates, writes the checkpoints into ``out`` (a path
that must exist on the node rank 0 runs on: a shared file system on a cluster) and reports each epoch's metrics to
Ray Train. The data paths must be readable at the same path on every worker's node.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

__all__ = ["train_on_ray"]


def _worker(config: dict) -> None:
    """One Ray Train worker (``train_loop_per_worker``): builds the data and model and runs :meth:`Trainer.fit`."""
    import ray.train  # lazy: heavy ray
    import ray.train.torch  # lazy: heavy ray

    from aerodaas.training.config import TrainConfig  # lazy: heavy pydantic
    from aerodaas.training.loop import Trainer  # lazy: optional onnx, torch; heavy cv2, numpy, pydantic
    from aerodaas.training.sets import load_training_data  # lazy: heavy cv2, numpy, pydantic
    from aerodaas.training.session import build_model  # lazy: optional onnx, torch; heavy cv2, numpy, onnxruntime, pydantic

    cfg = TrainConfig.model_validate(config)
    ctx = ray.train.get_context()
    data = load_training_data(cfg)
    model = build_model(cfg, data.names)
    trainer = Trainer(cfg, data, model, rank=ctx.get_world_rank(), world=ctx.get_world_size(),
                      on_epoch=_report_epoch)
    trainer.net = ray.train.torch.prepare_model(trainer.model, move_to_device=cfg.use_gpu)
    trainer.fit(cfg.out)


def _report_epoch(res) -> None:
    import ray.train  # lazy: heavy ray

    ray.train.report({"epoch": res.epoch, "loss": res.loss, "mean_ap50": res.mean_ap50,
                      "metrics": json.dumps([asdict(m) for m in res.metrics])})


def train_on_ray(cfg) -> dict:
    """Run ``cfg`` (a :class:`aerodaas.training.config.TrainConfig` with ``workers >= 1``) as a Ray Train job on the
    connected Ray cluster; returns the last reported metrics. Raises ``ray.train.TrainingFailedError`` (what a
    worker raised) when the job fails."""
    from ray.train import RunConfig, ScalingConfig  # lazy: heavy ray
    from ray.train.torch import TorchTrainer  # lazy: heavy ray

    out = Path(cfg.out).resolve()
    trainer = TorchTrainer(
        _worker,
        train_loop_config=cfg.model_copy(update={"out": out}).model_dump(mode="json"),
        scaling_config=ScalingConfig(num_workers=cfg.workers, use_gpu=cfg.use_gpu,
                                     resources_per_worker=None if cfg.use_gpu else {"CPU": 1}),
        run_config=RunConfig(name="aerodaas-train", storage_path=str(out / "ray_train")),
    )
    result = trainer.fit()
    return dict(result.metrics or {})
