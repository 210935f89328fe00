"""Textures reduced to the mean linear colour a diffuse albedo can hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._common import Notes


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def image_mean(image, raw: bool = False) -> np.ndarray:
    """Mean linear RGB of an 8-bit sRGB image (a PIL image or an array)."""
    a = np.asarray(image.convert("RGB") if hasattr(image, "convert") else image)
    a = a.reshape(-1, a.shape[-1])[:, :3].astype(np.float64) / 255.0
    return (a if raw else _srgb_to_linear(a)).mean(axis=0)


def texture_mean(img_path: Path, path: Path, notes: Notes, what: str) -> np.ndarray:
    try:
        from PIL import Image  # (a scikit-image dependency)

        with Image.open(img_path) as im:
            mean = image_mean(im)
    except (OSError, ValueError) as exc:
        notes.approx(f"{what}: texture {img_path.name} unreadable ({exc}): factor 1")
        return np.ones(3)
    notes.approx(f"{what}: texture {img_path.name} reduced to its mean colour")
    return mean


# -- glTF 2.0 --------------------------------------------------------------
