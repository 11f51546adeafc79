"""Options of the point-cloud-to-textured-mesh conversion (thesis chapter 6).

Two bounds steer the whole conversion, as in the thesis (6.4: "the only parameters
necessary for the conversion are an error bound for the mesh simplification and an error
threshold for the texture generation"):

* ``mesh_error`` (or ``faces``): the QEM simplification (6.1) stops at the coarsest mesh
  whose two-sided distance to the surfels stays below ``mesh_error`` times the diagonal of
  the cloud's bounding box (or at ``faces`` triangles);
* ``texture_error``: a patch is refined (6.2.1) until its error (6.1), normalised by the
  surfel area of the triangle, is below it (RGB distance in [0, sqrt(3)]; for the normal
  texture the same number bounds ``1 - n_s . n_t``, eq. 6.2).
"""

from __future__ import annotations

from dataclasses import dataclass

from unmesh._validate import scalar
from unmesh.errors import InputError

__all__ = ["ConvertOptions"]


def _pow2(value: int, name: str, lo: int, hi: int) -> int:
    v = int(value)
    if v != value or v < lo or v > hi or v & (v - 1):
        raise InputError(f"{name}: expected a power of two in [{lo}, {hi}], got {value!r}")
    return v


@dataclass(frozen=True)
class ConvertOptions:
    """Parameters of :func:`unmesh.convert.to_textured_mesh`.

    Parameters
    ----------
    mesh_error : float
        Largest two-sided distance between mesh and surfels, relative to the bounding-box
        diagonal of the cloud (6.1). Default 0.005 (Igea: 1,854 triangles, PSNR >= 30 dB in
        six views; 0.01 gives 632 triangles whose patches distort over the nose and lips).
    faces : int, optional
        Target triangle count instead of ``mesh_error`` (then the error is only reported).
    texture_error : float
        Threshold of the per-patch error (6.1): area-weighted mean RGB distance between the
        surfel colours and the bilinear texture at the surfel centres. Default 0.02.
    normal_error : float
        Threshold of the normal error (mean ``1 - N_s . N_t``, eq. 6.2). Default 0.005 (about
        6 degrees).
    normal_map : bool
        Bake a tangent-space normal texture (6.2) besides the colour texture.
    page_size : int
        Largest atlas page edge (a power of two); the atlas uses the smallest page that
        holds the patches, and several pages when one of this size is not enough (6.3).
    mipmaps : bool
        Also assemble half- and quarter-resolution atlases in the same layout (6.5).
    depth_map : bool
        Also bake a depth (displacement) texture (6.2): the height of the surface above each
        triangle's plane, world units (OBJ output: ``disp``; .glb files carry none).
    depth_error : float
        With ``depth_map``: threshold of the depth error, the mean distance between the
        surfels' heights above their triangle and the bilinear depth texture, relative to the
        bounding-box diagonal; patches are refined until it holds too. Default 0.0005 (a tenth
        of the default mesh error).
    fit_mesh : bool
        Move the simplified mesh's vertices along their normals to the least-squares fit of
        the surfel centres (:func:`unmesh.convert.fit.fit_vertices`): QEM leaves the faces
        as chords inside convex and outside concave parts, which shifts the texels seen at
        grazing angles and the outline.
    grid_factor : float
        Marching-cubes cell edge in units of the median surfel radius.
    max_level : int
        Largest refinement level: patches have at most ``2**max_level`` texels along
        their longest edge (besides the d_min / (2 sqrt 2) cap of 6.2.1).
    backend : {"mls", "poisson"}
        Surface reconstruction: MLS implicit function + marching cubes, or screened
        Poisson (Open3D, only where installed).
    progress : bool
        Progress bars per stage.

    Example
    -------
    >>> ConvertOptions(faces=1000).faces
    1000
    """

    mesh_error: float = 0.005
    faces: int | None = None
    texture_error: float = 0.02
    normal_error: float = 0.005
    normal_map: bool = True
    page_size: int = 2048
    mipmaps: bool = False
    depth_map: bool = False
    depth_error: float = 0.0005
    fit_mesh: bool = True
    grid_factor: float = 3.0
    max_level: int = 7
    backend: str = "mls"
    progress: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "mesh_error", scalar(self.mesh_error, "mesh_error", 1e-7, 1.0))
        if self.faces is not None:
            f = int(self.faces)
            if f != self.faces or f < 4:
                raise InputError(f"faces: expected an integer >= 4, got {self.faces!r}")
            object.__setattr__(self, "faces", f)
        object.__setattr__(self, "texture_error", scalar(self.texture_error, "texture_error", 1e-6, 2.0))
        object.__setattr__(self, "depth_error", scalar(self.depth_error, "depth_error", 1e-9, 1.0))
        object.__setattr__(self, "normal_error", scalar(self.normal_error, "normal_error", 1e-7, 2.0))
        object.__setattr__(self, "page_size", _pow2(self.page_size, "page_size", 64, 16384))
        object.__setattr__(self, "grid_factor", scalar(self.grid_factor, "grid_factor", 0.5, 20.0))
        lvl = int(self.max_level)
        if lvl != self.max_level or not 1 <= lvl <= 12:
            raise InputError(f"max_level: expected an integer in [1, 12], got {self.max_level!r}")
        object.__setattr__(self, "max_level", lvl)
        if self.backend not in ("mls", "poisson"):
            raise InputError(f"backend: expected 'mls' or 'poisson', got {self.backend!r}")
