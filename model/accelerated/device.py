"""The device an accelerated run asks for: ``"cpu"``, ``"gpu"`` (the first GPU JAX sees:
CUDA with the ``jax[cuda12]`` extra, or ROCm) or ``"auto"`` (a GPU if there is one, else the
CPU). Asking for a GPU where JAX sees none is one
:class:`nematic_solids.model.errors.DeviceUnavailable` naming the devices there are and the install
line."""

from __future__ import annotations

import jax

from ..accelerated_support import DEVICES
from ..errors import DeviceUnavailable

__all__ = ["DEVICES", "describe", "select_device"]


def _devices(platform: str) -> list[jax.Device]:
    """JAX's devices of one platform ("cpu", "gpu"); none where its backend is absent."""
    try:
        return list(jax.devices(platform))
    except RuntimeError:  # jax: "Unknown backend" / "Backend 'gpu' failed to initialize"
        return []


def select_device(name: str = "cpu") -> jax.Device:
    """The device called ``name`` (:data:`~nematic_solids.model.accelerated_support.DEVICES`);
    raises
    :class:`nematic_solids.model.errors.DeviceUnavailable` for a GPU that is not there, and for a
    name not in :data:`~nematic_solids.model.accelerated_support.DEVICES`."""
    if name not in DEVICES:
        raise DeviceUnavailable(f"unknown device {name!r}: ask for one of {', '.join(DEVICES)}")
    if name in ("gpu", "auto"):
        gpus = _devices("gpu")
        if gpus:
            return gpus[0]
        if name == "gpu":
            have = ", ".join(sorted({d.platform for d in jax.devices()})) or "none"
            raise DeviceUnavailable(
                f"a GPU was asked for, but JAX {jax.__version__} sees none (devices here: "
                f"{have}); on a machine with an NVIDIA GPU install pip install -e '.[accel]' "
                "'jax[cuda12]', or ask for device 'cpu' or 'auto'"
            )
    return _devices("cpu")[0]


def describe(device: jax.Device) -> str:
    """``platform:kind`` of a device, for benchmark files and run records (e.g.
    ``cpu:cpu``, ``gpu:NVIDIA A100-SXM4-40GB``)."""
    return f"{device.platform}:{getattr(device, 'device_kind', device.platform)}"
