"""``--backend ray``: image ranges rendered by Ray actors (one GL context each), files written by
the driver, so a cluster needs no shared file system. Output is byte-identical to the local
backend because every image depends only on ``(seed, index)``."""

from __future__ import annotations

from types import ModuleType

from tqdm import tqdm

from data_gen.config import GenerationConfig
from data_gen.producer import ImageProducer, write_files

CHUNK = 4


def import_ray() -> ModuleType:
    """Imports Ray or raises ``ValueError`` telling how to install it."""
    try:
        import ray
    except ImportError as error:
        raise ValueError("backend: 'ray' needs the optional dependency; install it with "
                         "`pip install 'paz6d[ray]'`") from error
    return ray


class _Renderer:
    """Ray actor body: one :class:`data_gen.producer.ImageProducer` for its lifetime."""

    def __init__(self, config: GenerationConfig):
        self.producer = ImageProducer(config)

    def produce(self, indices: list[int]) -> list[dict[str, bytes]]:
        return [self.producer.encode(self.producer.render(index)) for index in indices]


def run_with_ray(config: GenerationConfig, pending: list[int], workers: int, address: str | None,
                 progress: tqdm) -> int:
    """Renders ``pending`` on ``workers`` Ray actors; returns the number of files written."""
    ray = import_ray()
    started_here = not ray.is_initialized()
    if started_here:
        if address is None:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, configure_logging=False)
        else:
            ray.init(address=address, log_to_driver=False, configure_logging=False)
    try:
        actor_class = ray.remote(num_cpus=1)(_Renderer)
        actors = [actor_class.remote(config) for _ in range(workers)]
        pool = ray.util.ActorPool(actors)
        chunks = [pending[start:start + CHUNK] for start in range(0, len(pending), CHUNK)]
        written = 0
        for results in pool.map_unordered(lambda actor, chunk: actor.produce.remote(chunk), chunks):
            for files in results:
                written += write_files(config.out, files)
                progress.update(1)
        for actor in actors:
            ray.kill(actor)
        return written
    finally:
        if started_here:
            ray.shutdown()
