"""The torch devices a config may name: ``cpu`` and the CUDA devices this machine has."""

from __future__ import annotations

from shared.config import ConfigError

__all__ = ["check_device"]


def check_device(device: str, option: str) -> None:
    """Raise :class:`ConfigError` naming ``option`` if ``device`` is not a torch device this machine has.

    Args:
        device: E.g. ``cpu``, ``cuda``, ``cuda:1``.
        option: The config option it came from, e.g. ``planner.device`` (the error names it).
    """
    if device == "cpu":
        return  # every machine has it: no torch import for the common case (a config validated without a model)
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f"{option}: {device!r} is not a torch device ({exc})") from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise ConfigError(f"{option}: {device!r} asked for, but torch sees no CUDA device here "
                              f"(torch {torch.__version__}, CUDA build: {torch.version.cuda or 'no'})")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ConfigError(f"{option}: {device!r}: only {torch.cuda.device_count()} CUDA device(s)")
    elif dev.type != "cpu":
        raise ConfigError(f"{option}: {device!r}: only cpu and cuda are supported")
