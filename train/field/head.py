"""A head of the scene's own in torch (`FitConfig.head`): the shared decoder with its last layer refitted for one
scene, carried as the metadata's h= text (`snapshot3d.head`: numpy, the format and the runtime's side).

The last layer maps the last hidden layer (N, H) to (N, 4) density logit and rgb logits; its [W | b] is (4, H + 1).
Fitted from the shared layer at `FitConfig.head_lr`; in the fit's last phase through the 8-bit codes it is carried
as (one step for the whole difference from the shared layer), with identity gradient."""
from __future__ import annotations

import copy

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from snapshot3d.head import CODE_MAX, encode_head, head_weights

from .field import Decoder, frozen

__all__ = ["HeadDecoder", "own_head", "head_text", "with_head", "last_layer"]


def last_layer(decoder: Decoder) -> Tensor:
    """A decoder's last layer [W | b] (4, H + 1), detached."""
    lin = getattr(decoder, f"l{decoder.layers}")
    return torch.cat([lin.weight, lin.bias[:, None]], 1).detach()


def _carried(delta: Tensor) -> Tensor:
    """delta (4, H + 1) -> its value after the 8-bit codes of one step (`snapshot3d.head`), identity gradient."""
    step = torch.clamp(delta.detach().abs().max(), min=1e-6) / CODE_MAX
    return delta + (torch.round(delta.detach() / step) * step - delta.detach())


class HeadDecoder(Decoder):
    """The shared decoder, frozen, with a last layer of the scene's own (trainable). `shared` (4, H + 1): the
    shared decoder's last layer it started from, the reference of the carried difference. `quantize`: the last
    layer as its codes carry it (the fit's last phase)."""

    def __init__(self, decoder: Decoder):
        super().__init__(decoder.hidden, decoder.layers)
        self.load_state_dict(decoder.state_dict())
        base = decoder.shared if isinstance(decoder, HeadDecoder) else last_layer(decoder)
        self.register_buffer("shared", base.detach().clone(), persistent=False)
        self.quantize = False
        for name, p in self.named_parameters():
            p.requires_grad_(name.startswith(f"l{self.layers}."))

    def head_out(self, h: Tensor) -> Tensor:
        full = torch.cat([getattr(self, f"l{self.layers}").weight, getattr(self, f"l{self.layers}").bias[:, None]], 1)
        if self.quantize:
            full = self.shared + _carried(full - self.shared)
        return F.linear(h, full[:, :-1], full[:, -1])

    def head_parameters(self) -> list:
        return [p for p in self.parameters() if p.requires_grad]


def own_head(decoder: Decoder) -> HeadDecoder:
    """A head of the scene's own, starting from `decoder`'s last layer (a `HeadDecoder` goes on from its own), on
    `decoder`'s device."""
    dev = next(decoder.parameters()).device
    return HeadDecoder(decoder).to(dev)


def head_text(decoder: HeadDecoder) -> str:
    """The h= text of `decoder`'s last layer (its difference from the shared one, as 8-bit codes)."""
    return encode_head((last_layer(decoder) - decoder.shared).cpu().numpy())


def with_head(decoder: Decoder, text: str | None) -> Decoder:
    """The shared `decoder` with the scene's carried head `text` as its last layer (frozen; a copy), or `decoder`
    itself when `text` is None. The weights are `snapshot3d.head.head_weights`', what the runtime renders with."""
    if text is None:
        return decoder
    shared = last_layer(decoder).cpu().numpy().astype(np.float32)
    full = torch.from_numpy(head_weights(shared, text)).to(last_layer(decoder).device)
    out = copy.deepcopy(decoder)
    lin = getattr(out, f"l{out.layers}")
    with torch.no_grad():
        lin.weight.copy_(full[:, :-1])
        lin.bias.copy_(full[:, -1])
    return frozen(out)
