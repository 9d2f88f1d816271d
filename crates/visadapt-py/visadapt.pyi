"""Type stubs of `visadapt`: what a human observer sees in an HDR scene (Ferwerda et al. 1996).

Luminances are in cd/m² (photopic) or scotopic cd/m², times in seconds, angles in degrees.
Images are numpy float32 arrays, rows top to bottom.
"""

from os import PathLike
from typing import Any, Dict, List, Literal, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt
from typing_extensions import Unpack

__version__: str

Path = Union[str, "PathLike[str]"]
Array = npt.NDArray[np.floating[Any]]
Float32 = npt.NDArray[np.float32]
Report = Dict[str, Any]

Projection = Literal[
    "perspective",
    "angular fisheye",
    "hemispherical fisheye",
    "cylindrical",
    "planisphere",
    "parallel",
]

class ViewDict(TypedDict, total=False):
    projection: Projection
    horizontal_fov_deg: float
    vertical_fov_deg: float

Chromaticities = Tuple[
    Tuple[float, float], Tuple[float, float], Tuple[float, float], Tuple[float, float]
]

class Conditions(TypedDict, total=False):
    """The viewing conditions every mapping function takes as keywords (None: the default)."""

    peak: Optional[float]
    """Rescale the image so that its highest visible luminance is this, cd/m² (excludes scale)."""
    scale: Optional[float]
    """Multiply the image by this to get cd/m²."""
    display_max: float
    """The display's maximum luminance L_dmax, cd/m² (default 80)."""
    display_adaptation: Optional[float]
    """The display observer's adaptation L_da, cd/m² (default display_max / 2)."""
    world_adaptation: Optional[float]
    """The world observer's cone adaptation L_wa, cd/m² (default half the highest visible)."""
    scotopic_adaptation: Optional[float]
    """The world observer's rod adaptation, scotopic cd/m²."""
    hot_pixel_fraction: float
    """Fraction of pixels allowed above the highest visible luminance (default 1e-3)."""
    fov: Optional[float]
    """Horizontal field of view, degrees (default the file's view, else 60)."""
    projection: Optional[Literal["perspective", "fisheye"]]
    """The projection of `fov`: perspective (under 180 degrees, the default) or angular fisheye."""
    acuity: bool
    """Apply the acuity blur, Eq. 7 (default True)."""
    acuity_threshold: Optional[Literal["pooled", "envelope"]]
    """Eq. 7's threshold contrast: "pooled" (the JND metric's, default) or "envelope" (the paper's)."""
    white_point: Optional[str]
    """Scene white adapted to D65 by CAT16: "auto" (the file's, default), "none" (the paper), "E", "D65" or "x,y"."""
    adaptation: Optional[Literal["global", "local"]]
    """One adaptation level for the scene (the paper, default) or one per pixel."""
    adaptation_radius: Optional[float]
    """The neighbourhood of local adaptation, degrees (default 1; needs adaptation="local")."""
    glare: bool
    """Veiling glare in the eye, CIE 135/1 glare spread function (default False)."""
    age: Optional[float]
    """The glare observer's age, years (default 25; needs glare=True)."""
    pigmentation: Optional[float]
    """The glare observer's eye pigmentation, 0 very dark to 1.2 light blue (default 0.5; needs glare=True)."""
    undershoot: Optional[Literal["clamped", "in-mapping"]]
    """Time course: whether Baker's dip enters the mapping ("in-mapping", the paper) or not ("clamped", default)."""

class DecodeError(ValueError):
    """A file is not valid data of its format (truncated, corrupt or inconsistent)."""

class UnsupportedError(DecodeError):
    """A file uses something visadapt does not read (or is of no format it knows)."""

class HdrImage:
    """An HDR image in absolute units (XYZ with Y in cd/m², optional scotopic plane)."""

    @property
    def xyz(self) -> Float32:
        """CIE XYZ, H x W x 3 float32, Y in cd/m² (a new copy on each access)."""
    @property
    def scotopic(self) -> Optional[Float32]:
        """Scotopic luminance, H x W float32 in scotopic cd/m², or None."""
    @property
    def view(self) -> Optional[ViewDict]:
        """The recorded camera view (projection, fields of view in degrees), or None."""
    @property
    def width(self) -> int:
        """Width in pixels."""
    @property
    def height(self) -> int:
        """Height in pixels."""
    @property
    def absolute_units(self) -> bool:
        """True when the values are known to be cd/m²."""

def read(
    path: Path,
    max_pixels: Optional[int] = None,
    max_memory_bytes: Optional[int] = None,
    *,
    scale: Optional[float] = None,
) -> HdrImage:
    """Read a Radiance, OpenEXR or PFM file, or an 8/16-bit PNG, JPEG or TIFF photograph
    (format from its first bytes).

    A photograph is read with the sRGB curve undone, Rec. 709 primaries, a D65 white and
    code-value white at Y = 1 (relative units): state its luminance in cd/m² with
    `map(image, scale=...)` or `peak=`.

    scale= multiplies every value by the file's unit in cd/m² (e.g. 179 for radiance in
    W/sr/m²) as `map(image, scale=...)` would, applied by the decoder as it converts;
    `absolute_units` stays what the file says.

    Raises OSError (unreadable), DecodeError (corrupt), UnsupportedError (unknown format or
    feature), ValueError (larger than max_pixels, default 2**28, or than the memory budget
    max_memory_bytes, default 12 GiB; a scale that is not positive and finite).
    """

def from_array(
    xyz: Array,
    scotopic: Optional[Array] = None,
    view: Union[ViewDict, float, None] = None,
) -> HdrImage:
    """An image from XYZ (H x W x 3, cd/m²) and optionally scotopic (H x W, scotopic cd/m²).

    float32 or float64, any memory order. `view`: a dict as HdrImage.view, or a horizontal
    field of view in degrees (perspective).
    """

def from_rgb(
    rgb: Array,
    primaries: Union[Literal["rec709", "srgb", "radiance"], Chromaticities, None] = None,
    scale: float = 1.0,
    scotopic: Optional[Array] = None,
    view: Union[ViewDict, float, None] = None,
) -> HdrImage:
    """An image from linear RGB (H x W x 3) in `primaries` (default Rec. 709), times `scale` to cd/m²."""

def chart(white: float = 100.0, fov: Optional[float] = None, gratings: bool = True) -> HdrImage:
    """The paper's test scene (Fig. 11) with its white at `white` cd/m²; `fov` in degrees."""

def write(
    path: Path,
    data: Union[HdrImage, Array],
    *,
    bits: int = 8,
    png_compression: Literal["fast", "fastest", "rle", "fdeflate"] = "fast",
    quality: int = 90,
    display_max: float = 80.0,
) -> None:
    """Write .png/.jpg/.exr atomically.

    `png_compression`: "fast", "fastest", "rle" or "fdeflate" (lossless at every level).

    `data`: a display image (H x W x 3, linear sRGB relative to display_max cd/m²), an
    HdrImage (.exr) or an H x W plane in cd/m² (.exr).
    """

def map(
    image: HdrImage,
    **conditions: Unpack[Conditions],
) -> Tuple[Float32, Report]:
    """Map an image for display as the observer adapted to it sees it.

    Returns (display, report): display H x W x 3 float32 linear sRGB relative to
    display_max (cd/m²); report the dict of `visadapt map --json`.
    """

def observer(
    luminance: float, scotopic: Optional[float] = None, display_max: float = 80.0
) -> Report:
    """The model's quantities for an observer adapted to `luminance` cd/m² (`observer --json`)."""

def timecourse(
    from_: float, to: float, times: Sequence[float], display_max: float = 80.0
) -> List[Report]:
    """Adaptation over time after the luminance changes from `from_` to `to` cd/m² (`timecourse --json`)."""

def visible(
    reference: HdrImage,
    test: HdrImage,
    **conditions: Unpack[Conditions],
) -> Tuple[Float32, Report]:
    """JNDs per pixel between two images (H x W float32) and the `visible --json` summary."""

def tolerance(
    image: HdrImage,
    **conditions: Unpack[Conditions],
) -> Tuple[Float32, Report]:
    """The invisible luminance error per pixel (H x W float32, cd/m²) and the `tolerance --json` summary."""

class Adaptation:
    """An observer whose thresholds adapt over time (Sec. 3.5)."""

    def __init__(self, luminance: float, scotopic: Optional[float] = None) -> None:
        """Fully adapted to `luminance` cd/m² (scotopic default luminance x 2.261)."""
    def step(
        self,
        dt_seconds: float,
        target: Union[HdrImage, Report, float, Tuple[float, float]],
        **conditions: Unpack[Conditions],
    ) -> None:
        """View the current world for `dt_seconds`, then switch to `target`'s luminance."""
    def thresholds(self) -> Report:
        """Current thresholds, excess over steady state, acuity, time since the change."""
    def map(
        self,
        image: HdrImage,
        **conditions: Unpack[Conditions],
    ) -> Tuple[Float32, Report]:
        """`map` with the current (not steady-state) thresholds, Eq. 8-9."""
