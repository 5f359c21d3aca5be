// Client-side projection of an element into a camera image, so the drawn element follows a vertex drag on the
// map without a server round trip: the element is lifted with the heights the server gave (each point takes
// the z of the nearest lifted vertex), mapped into the camera by cam_from_site and through K, clipped to the
// space in front of the camera. The server's projection replaces it once the edit is saved.

/** Points closer to the camera plane than this (metres) are cut away, as the server cuts them. */
export const NEAR_M = 0.5;
/** Spacing (metres) at which a dragged polyline is resampled (the server's lift spacing), so a long segment
 * follows the ground. */
export const RESAMPLE_M = 0.5;

/**
 * The z of the lifted point nearest (in x, y) to (x, y); null when there is no lifted point.
 * @param {number} x
 * @param {number} y
 * @param {number[][]} lifted [[x, y, z], ...] in site metres
 */
export function nearestZ(x, y, lifted) {
  let best = Infinity;
  let z = null;
  for (const p of lifted) {
    const d = (p[0] - x) * (p[0] - x) + (p[1] - y) * (p[1] - y);
    if (d < best) {
      best = d;
      z = p[2];
    }
  }
  return z;
}

/**
 * A 2D polyline (the element as it is now on the map) lifted to 3D: resampled every `step` metres, each point
 * with the z of the nearest vertex the server lifted, so an unmoved vertex keeps its own height and a moved one
 * takes its nearest neighbour's. Empty when nothing was lifted.
 * @param {number[][]} points [[x, y], ...] site metres
 * @param {number[][]} lifted the server's points_3d
 * @param {number} [step]
 * @returns {number[][]}
 */
export function liftPolyline(points, lifted, step = RESAMPLE_M) {
  if (!lifted.length || !points.length) return [];
  const out = [];
  const add = (x, y) => out.push([x, y, /** @type {number} */ (nearestZ(x, y, lifted))]);
  for (let i = 0; i + 1 < points.length; i++) {
    const [ax, ay] = points[i];
    const [bx, by] = points[i + 1];
    const n = Math.max(1, Math.ceil(Math.hypot(bx - ax, by - ay) / step));
    for (let k = 0; k < n; k++) add(ax + ((bx - ax) * k) / n, ay + ((by - ay) * k) / n);
  }
  const last = points[points.length - 1];
  add(last[0], last[1]);
  return out;
}

/**
 * A site point in the camera frame: R p + t (x right, y down, z forward).
 * @param {number[][]} camFromSite 4x4, rows
 * @param {number[]} p [x, y, z]
 */
export function toCamera(camFromSite, p) {
  const m = camFromSite;
  return [0, 1, 2].map((r) => m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3]);
}

/**
 * Image pixel of a camera-frame point in front of the camera: K c, divided by its third row.
 * @param {number[][]} K 3x3
 * @param {number[]} c
 */
export function toPixel(K, c) {
  const w = K[2][0] * c[0] + K[2][1] * c[1] + K[2][2] * c[2];
  return [(K[0][0] * c[0] + K[0][1] * c[1] + K[0][2] * c[2]) / w, (K[1][0] * c[0] + K[1][1] * c[1] + K[1][2] * c[2]) / w];
}

/**
 * The pieces of a 3D polyline in front of the camera, in full-resolution image pixels: a segment crossing the
 * near plane is cut there, so a line passing behind the camera splits into separate pieces. Drawing clips
 * them to the image.
 * @param {{K: number[][], cam_from_site: number[][]}} camera from /images/{token}/camera
 * @param {number[][]} points3d site metres
 * @returns {number[][][]}
 */
export function projectPolyline(camera, points3d) {
  const cams = points3d.map((p) => toCamera(camera.cam_from_site, p));
  const pieces = [];
  let piece = [];
  const flush = () => {
    if (piece.length > 1) pieces.push(piece);
    piece = [];
  };
  for (let i = 0; i < cams.length; i++) {
    const c = cams[i];
    const prev = i > 0 ? cams[i - 1] : null;
    if (prev && (prev[2] >= NEAR_M) !== (c[2] >= NEAR_M)) {
      const t = (NEAR_M - prev[2]) / (c[2] - prev[2]);
      const cut = [0, 1, 2].map((k) => prev[k] + t * (c[k] - prev[k]));
      piece.push(toPixel(camera.K, cut));
      if (c[2] < NEAR_M) flush();
    }
    if (c[2] >= NEAR_M) piece.push(toPixel(camera.K, c));
  }
  flush();
  return pieces;
}
