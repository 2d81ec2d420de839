"""The five reversible kernel pairs of the sampler, pure functions of ``(rng, world, data)``.

Each kernel returns a :class:`Proposal` (new world, log proposal ratio, changed slots) or ``None``
(no valid move: the chain stays). See docs/sampler.md for every forward and reverse density.
"""

from semmap_pp.model import KIND_NAMES, KernelSettings, settings_from_mapping
from semmap_pp.sampler.kernels.add_remove import add_remove
from semmap_pp.sampler.kernels.allocate_delete import allocate_delete
from semmap_pp.sampler.kernels.data import KernelData, build_data, data_from_frame
from semmap_pp.sampler.kernels.interchange import interchange
from semmap_pp.sampler.kernels.proposal import Kernel, Mix, Proposal
from semmap_pp.sampler.kernels.shrink_dilate import shrink_dilate
from semmap_pp.sampler.kernels.split_merge import split_merge

KERNELS = {k.kind: k for k in (add_remove, split_merge, shrink_dilate, allocate_delete, interchange)}


def default_mix(settings: KernelSettings | None = None) -> Mix:
    """The mix of all five pairs with the weights of ``settings`` (defaults: :class:`KernelSettings`)."""
    weights = (settings or KernelSettings()).weights
    return Mix([(KERNELS[kind], w) for kind, w in weights])


__all__ = ["KERNELS", "KIND_NAMES", "Kernel", "KernelData", "KernelSettings", "Mix", "Proposal",
           "add_remove", "allocate_delete", "build_data", "data_from_frame", "default_mix", "interchange",
           "settings_from_mapping", "shrink_dilate", "split_merge"]
