"""The papermill engine the notebooks are executed with: `papermill --engine gcdt ...`.

papermill's default engine starts each kernel over TCP with no transport encryption, and
ipykernel (>= 7.3) warns about it on every start ("Kernel is running over TCP without
encryption"). papermill reads no Jupyter config files and has no flag for it, so this engine is
the default one with `KernelManager.transport_encryption = "auto"`: jupyter_client then gives
the kernel CurveZMQ keys when its kernelspec declares support, as ipykernel's own does (other
kernels start unencrypted, and ipykernel's warning rightly stays). Registered in pyproject.toml.
"""

from __future__ import annotations

from typing import Any

from papermill.engines import NBClientEngine
from traitlets.config import Config


class EncryptedNBClientEngine(NBClientEngine):
    """papermill's `nbclient` engine, with the kernel's transport encrypted where supported."""

    @classmethod
    def execute_managed_notebook(cls, nb_man: Any, kernel_name: str, **kwargs: Any) -> Any:
        config = Config({"KernelManager": {"transport_encryption": "auto"}})
        return super().execute_managed_notebook(nb_man, kernel_name, config=config, **kwargs)
