"""Independent float64 evaluations of the mixel integral, to validate the renderer (pure numpy / scipy).

Nothing here shares code with the render layer: geometry is redone in numpy from the poses, masks are read
from their analytic profiles (the definition of the mask), and visibility is solved analytically.

* :func:`mixel_irradiance_gl`: Gauss-Legendre quadrature over the detector and a rectangle of screen
  coordinates of ``E = 1/A_d int_det int_screen L T(x_m) cos(t_d) cos(t_s) / r^2 dA_s dA_d`` for any pose
  of mixel and screen and any mask profile (no occluders). Accurate when the integrand is smooth over the
  rectangle (the rectangle inside the aperture's view from every detector point).
* :func:`open_aperture_view_factor_irradiance`: a uniform Lambertian emitter rectangle seen through an open
  aperture, with convex opaque boxes (other mixels' bodies, plates) in between: for each detector point the
  visible part of the emitter is (emitter ∩ aperture projection) minus the boxes' shadows, and its view factor
  is exact (Lambert's contour formula for polygons); Gauss-Legendre over the detector.
* :func:`mixel_irradiance_polygon`: the mixel integral for any pose, mask profile and radiance function, with
  the aperture's shadow clipped exactly: for each detector node the part of the screen rectangle seen through
  the aperture is a convex polygon (the rectangle cut by the half-planes of the view pyramid from that node
  through the aperture), integrated by Gauss-Legendre on the triangles of a fan. The integrand is then smooth
  on every triangle, so it converges where :func:`mixel_irradiance_gl` has the aperture edge inside its panels.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from mincam_sim.masks.profiles import NUMPY_OPS
from mincam_sim.model.geometry import clip_polygon_halfspace
from mincam_sim.model.optics import Mixel
from mincam_sim.scene.display import Screen


def _gl(n: int, lo: float, hi: float, panels: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Composite Gauss-Legendre nodes and weights on [lo, hi]."""
    x, w = np.polynomial.legendre.leggauss(n)
    edges = np.linspace(lo, hi, panels + 1)
    nodes, weights = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        nodes.append(0.5 * (b - a) * x + 0.5 * (a + b))
        weights.append(0.5 * (b - a) * w)
    return np.concatenate(nodes), np.concatenate(weights)


def _transmission(mixel: Mixel, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    mask = mixel.mask
    if mask.profile is None:
        raise ValueError("the quadrature oracle reads masks from their analytic profile; this mask has none")
    t = np.asarray(mask.profile.evaluate(x_m, y_m, NUMPY_OPS), dtype=np.float64)
    inside = (np.abs(x_m) <= mask.width_m / 2) & (np.abs(y_m) <= mask.height_m / 2)
    return np.where(inside, t, 0.0)


def mixel_irradiance_gl(
    mixel: Mixel,
    screen: Screen,
    region_m: tuple[float, float, float, float],
    radiance=1.0,
    n_detector: int = 8,
    n_screen: int = 32,
    panels: int = 1,
) -> float:
    """Mean irradiance [W/m^2] on the detector from the screen rectangle ``region_m = (x0, x1, y0, y1)``.

    ``radiance`` is a number [W m^-2 sr^-1] or a function of screen coordinates ``(x_m, y_m)`` (x right,
    y up). Gauss-Legendre with ``n_detector`` nodes per detector axis and ``panels`` x ``n_screen`` per screen
    axis; no occluders.
    """
    s = mixel.detector_size_m
    dx, dw = _gl(n_detector, -s / 2, s / 2)
    x0, x1, y0, y1 = region_m
    sx, sw = _gl(n_screen, x0, x1, panels)
    sy, syw = _gl(n_screen, y0, y1, panels)
    gx, gy = np.meshgrid(sx, sy, indexing="ij")
    gw = np.outer(sw, syw)
    points = screen.to_world(gx, gy).reshape(-1, 3)
    normal = screen.pose.axes()[2]
    lum = radiance(gx, gy).ravel() if callable(radiance) else np.full(points.shape[0], float(radiance))
    local = mixel.pose.to_local(points)
    rot = mixel.pose.matrix()[:3, :3]
    total = 0.0
    for a, wa in zip(dx, dw, strict=True):
        for b, wb in zip(dx, dw, strict=True):
            x_d = np.array([a, b, 0.0])
            delta = local - x_d
            r2 = np.einsum("ij,ij->i", delta, delta)
            r = np.sqrt(r2)
            cos_d = delta[:, 2] / r
            cos_s = -(delta @ rot.T) @ normal / r
            t_mask = mixel.d_f_m / np.where(delta[:, 2] > 0, delta[:, 2], np.inf)
            xm = x_d[0] + delta[:, 0] * t_mask
            ym = x_d[1] + delta[:, 1] * t_mask
            trans = _transmission(mixel, -xm, ym)  # physical mask x is the viewer's right = -local x
            g = np.where((cos_d > 0) & (cos_s > 0), lum * trans * cos_d * cos_s / r2, 0.0)
            total += wa * wb * np.sum(gw.ravel() * g)
    return float(total / s**2)


# ---------------------------------------------------------------------------------------------- polygons
def _clip(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: convex polygon ``subject`` clipped by convex counter-clockwise polygon ``clip``."""
    out = subject
    for i in range(len(clip)):
        if len(out) == 0:
            break
        a, b = clip[i], clip[(i + 1) % len(clip)]
        edge = b - a

        def inside(p, a=a, edge=edge):
            return edge[0] * (p[1] - a[1]) - edge[1] * (p[0] - a[0]) >= 0

        src, out = out, []
        for j in range(len(src)):
            p, q = src[j], src[(j + 1) % len(src)]
            ip, iq = inside(p), inside(q)
            if ip:
                out.append(p)
            if ip != iq:
                d = q - p
                denom = edge[0] * d[1] - edge[1] * d[0]
                t = (edge[0] * (a[1] - p[1]) - edge[1] * (a[0] - p[0])) / denom if denom != 0 else 0.0
                out.append(p + t * d)
        out = np.array(out) if out else np.zeros((0, 2))
    return np.asarray(out)


def _ccw(poly: np.ndarray) -> np.ndarray:
    area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    return poly if area >= 0 else poly[::-1]


def polygon_view_factor(point: np.ndarray, normal: np.ndarray, vertices: np.ndarray) -> float:
    """View factor from a differential area (``point``, unit ``normal``) to a planar polygon in front of it
    (Lambert's contour formula: ``F = 1/(2 pi) sum gamma_i n . (R_i x R_i+1) / |R_i x R_i+1|``)."""
    if len(vertices) < 3:
        return 0.0
    total = 0.0
    for i in range(len(vertices)):
        r1 = vertices[i] - point
        r2 = vertices[(i + 1) % len(vertices)] - point
        cross = np.cross(r1, r2)
        norm = np.linalg.norm(cross)
        if norm == 0:
            continue
        gamma = np.arctan2(norm, np.dot(r1, r2))
        total += gamma * np.dot(normal, cross) / norm
    return abs(total) / (2 * np.pi)


def open_aperture_view_factor_irradiance(
    mixel: Mixel,
    screen: Screen,
    radiance: float,
    occluder_corners_m: list[np.ndarray] = (),
    n_detector: int = 12,
) -> float:
    """Mean irradiance [W/m^2] on the detector of an open-aperture mixel from a uniform screen, with convex
    opaque boxes (each given by its 8 world corners [m]) between the mask and the screen.

    Each box must lie entirely beyond the mask plane and in front of the screen (its shadow on the screen plane
    is then the convex hull of its projected corners). Each shadow's view factor is subtracted on its own, so
    the boxes' shadows must not overlap as seen from any detector point (overlapping shadows are counted
    twice): give one box per direction. The mask's transmission is ignored (open aperture).
    """
    right, up, normal = screen.pose.axes()
    center = np.asarray(screen.pose.position_m)
    m = mixel.pose.matrix()
    det_normal = m[:3, 2]
    hw, hh = mixel.mask.width_m / 2, mixel.mask.height_m / 2
    aperture = mixel.pose.to_world(np.array([[hw, hh, mixel.d_f_m], [-hw, hh, mixel.d_f_m],
                                             [-hw, -hh, mixel.d_f_m], [hw, -hh, mixel.d_f_m]]))
    screen_poly = np.array([[-screen.width_m / 2, -screen.height_m / 2], [screen.width_m / 2, -screen.height_m / 2],
                            [screen.width_m / 2, screen.height_m / 2], [-screen.width_m / 2, screen.height_m / 2]])

    def project(p0: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Screen coordinates of where rays from p0 through ``points`` meet the screen plane."""
        d = points - p0
        t = ((center - p0) @ normal) / (d @ normal)
        if np.any(t <= 1.0):
            raise ValueError("an occluder or the aperture is not between the detector and the screen plane")
        hit = p0 + t[:, None] * d - center
        return np.column_stack([hit @ right, hit @ up])

    def lift(poly: np.ndarray) -> np.ndarray:
        return center + poly[:, :1] * right + poly[:, 1:2] * up

    s = mixel.detector_size_m
    nodes, weights = _gl(n_detector, -s / 2, s / 2)
    total = 0.0
    for a, wa in zip(nodes, weights, strict=True):
        for b, wb in zip(nodes, weights, strict=True):
            p0 = mixel.pose.to_world(np.array([a, b, 0.0]))
            visible = _clip(_ccw(project(p0, aperture)), _ccw(screen_poly))
            f = polygon_view_factor(p0, det_normal, lift(visible)) if len(visible) >= 3 else 0.0
            for corners in occluder_corners_m:
                shadow2d = project(p0, np.asarray(corners))
                hull = shadow2d[ConvexHull(shadow2d).vertices]
                hidden = _clip(_ccw(hull), _ccw(visible)) if len(visible) >= 3 else np.zeros((0, 2))
                if len(hidden) >= 3:
                    f -= polygon_view_factor(p0, det_normal, lift(hidden))
            total += wa * wb * f
    return float(np.pi * radiance * total / s**2)


# ---------------------------------------------------------------------------------------------- exact shadow
def _triangle_rule(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Collapsed (Duffy) Gauss-Legendre rule on the reference triangle (0,0), (1,0), (1,1) -> barycentric form.

    Returns ``(u, uv, w)``: a point of triangle (p0, p1, p2) is ``p0 + u (p1 - p0) + uv (p2 - p1)`` and the
    weights ``w`` sum to 1/2 (the reference area); multiply by twice the triangle's area.
    """
    x, wx = np.polynomial.legendre.leggauss(n)
    x, wx = 0.5 * (x + 1), 0.5 * wx
    u, v = np.meshgrid(x, x, indexing="ij")
    w = np.outer(wx, wx) * u
    return u.ravel(), (u * v).ravel(), w.ravel()


def visible_polygon_screen_m(mixel: Mixel, screen: Screen, detector_point_world_m: np.ndarray,
                             region_m: tuple[float, float, float, float]) -> np.ndarray:
    """The part (convex polygon (k, 2), screen coordinates [m]) of the screen rectangle ``region_m = (x0, x1, y0,
    y1)`` that the detector point sees through the aperture: beyond the mask plane and inside the pyramid from
    the point through the aperture's four edges. Exact for any poses (no projection that could diverge)."""
    right, up, _ = screen.pose.axes()
    center = np.asarray(screen.pose.position_m, dtype=np.float64)
    d = np.asarray(detector_point_world_m, dtype=np.float64)
    hw, hh = mixel.mask.width_m / 2, mixel.mask.height_m / 2
    aperture = mixel.pose.to_world(np.array([[hw, hh, mixel.d_f_m], [-hw, hh, mixel.d_f_m],
                                             [-hw, -hh, mixel.d_f_m], [hw, -hh, mixel.d_f_m]]))
    mask_centre = mixel.pose.to_world(np.array([0.0, 0.0, mixel.d_f_m]))
    forward = mixel.pose.axes()[2]
    x0, x1, y0, y1 = region_m
    poly = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
    # half-spaces n . (p - q) >= 0 on the screen plane p = center + x right + y up
    planes = [(forward, mask_centre)]
    for i in range(4):
        n = np.cross(aperture[i] - d, aperture[(i + 1) % 4] - d)
        if n @ (mask_centre - d) < 0:
            n = -n
        planes.append((n, d))
    for n, q in planes:
        n = n / np.linalg.norm(n)
        poly = clip_polygon_halfspace(poly, np.array([n @ right, n @ up]), float(n @ (center - q)))
        if len(poly) < 3:
            return np.zeros((0, 2))
    return poly


def mixel_irradiance_polygon(
    mixel: Mixel,
    screen: Screen,
    region_m: tuple[float, float, float, float] | None = None,
    radiance=1.0,
    n_detector: int = 12,
    n_triangle: int = 16,
    detector_panels: int = 1,
    subdivisions: int = 0,
) -> float:
    """Mean irradiance [W/m^2] on the detector from the screen rectangle ``region_m = (x0, x1, y0, y1)``
    (screen coordinates [m]; default the whole screen), with the aperture's shadow clipped exactly.

    ``E = 1/A_d int_det int_vis(x_d) L T(x_m) cos(t_d) cos(t_s) / r^2 dA_s dA_d``: for each Gauss-Legendre
    detector node (``detector_panels`` x ``n_detector`` per axis) the visible polygon
    (:func:`visible_polygon_screen_m`) is split into a fan of triangles, each optionally split ``subdivisions``
    times into 4, and integrated with an ``n_triangle`` x ``n_triangle`` collapsed Gauss-Legendre rule. The
    mask's transmission is read from its analytic profile; ``radiance`` is a number [W m^-2 sr^-1] or a
    function of screen coordinates ``(x_m, y_m)``. No occluders (other bodies).
    """
    if region_m is None:
        region_m = (-screen.width_m / 2, screen.width_m / 2, -screen.height_m / 2, screen.height_m / 2)
    s = mixel.detector_size_m
    dx, dw = _gl(n_detector, -s / 2, s / 2, detector_panels)
    tu, tuv, tw = _triangle_rule(n_triangle)
    right, up, screen_normal = screen.pose.axes()
    center = np.asarray(screen.pose.position_m, dtype=np.float64)
    m = mixel.pose.matrix()
    rot = m[:3, :3]
    total = 0.0
    for a, wa in zip(dx, dw, strict=True):
        for b, wb in zip(dx, dw, strict=True):
            x_d = np.array([a, b, 0.0])
            d_world = mixel.pose.to_world(x_d)
            if (d_world - center) @ screen_normal <= 0:
                continue  # behind the emitting side
            poly = visible_polygon_screen_m(mixel, screen, d_world, region_m)
            if len(poly) < 3:
                continue
            tris = [np.stack([poly[0], poly[i], poly[i + 1]]) for i in range(1, len(poly) - 1)]
            for _ in range(subdivisions):
                split = []
                for p0, p1, p2 in tris:
                    m01, m12, m20 = (p0 + p1) / 2, (p1 + p2) / 2, (p2 + p0) / 2
                    split += [np.stack(t) for t in ((p0, m01, m20), (m01, p1, m12), (m20, m12, p2), (m01, m12, m20))]
                tris = split
            tri = np.array(tris)  # (k, 3, 2)
            p0, p1, p2 = tri[:, 0], tri[:, 1], tri[:, 2]
            e1, e2 = p1 - p0, p2 - p0
            area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
            pts = p0[:, None] + tu[None, :, None] * (p1 - p0)[:, None] + tuv[None, :, None] * (p2 - p1)[:, None]
            w = (area2[:, None] * tw[None, :]).ravel()
            sx, sy = pts[..., 0].ravel(), pts[..., 1].ravel()
            world = center + sx[:, None] * right + sy[:, None] * up
            lum = radiance(sx, sy) if callable(radiance) else np.full(sx.shape, float(radiance))
            delta = (world - np.asarray(mixel.pose.position_m)) @ rot - x_d  # local frame
            r2 = np.einsum("ij,ij->i", delta, delta)
            r = np.sqrt(r2)
            cos_d = delta[:, 2] / r
            cos_s = -(delta @ rot.T) @ screen_normal / r
            t_mask = mixel.d_f_m / delta[:, 2]
            xm = x_d[0] + delta[:, 0] * t_mask
            ym = x_d[1] + delta[:, 1] * t_mask
            mask = mixel.mask
            if mask.profile is None:
                raise ValueError("the quadrature oracle reads masks from their analytic profile; this mask has none")
            trans = np.asarray(mask.profile.evaluate(-xm, ym, NUMPY_OPS), dtype=np.float64) * np.ones_like(xm)
            g = lum * trans * np.clip(cos_d, 0, None) * np.clip(cos_s, 0, None) / r2
            total += wa * wb * float(np.sum(w * g))
    return float(total / s**2)
