/*
 * Plane-sweep stereo kernels (OpenCL C 1.2). Built after camera_model_shared.h
 * and plane_sweep_shared.h, whose functions they call; the C++ reference
 * sweep (plane_sweep_cpu.cpp) calls the same functions.
 *
 * Per plane: sweep_warp samples every supporting view at the plane's point of
 * each reference pixel; sweep_cost turns those samples into one aggregated
 * ZNCC cost per pixel in the cost volume. Once per frame, sweep_select picks
 * the best plane of each pixel.
 *
 * Global sizes are exactly the image (no bounds checks).
 *
 * Built with -DFM_CAM_SPACE=__global (camera parameters read in place) and
 * -DFM_SWEEP_VIEWS=N (the number of supporting views) and
 * -DFM_SWEEP_RADIUS=R (window radius) so that every loop has a compile-time
 * trip count and unrolls, and the sums stay in registers.
 */
#if !defined(FM_SWEEP_VIEWS) || !defined(FM_SWEEP_RADIUS)
#error "build with -DFM_SWEEP_VIEWS=<supporting views> -DFM_SWEEP_RADIUS=<window radius>"
#endif

/* warped[v * npix + pix]: intensity of view v at the plane point of ref pixel
 * pix, -1 where unusable. A zero ray marks a reference pixel that is masked
 * or outside the model's domain; self-masked pixels of the views' images hold
 * -1. A pixel of a tile whose samples no swept window reads
 * (needed[(plane * tiles_y + ty) * tiles_x + tx] == 0: the plane's active
 * tiles grown by one tile, which covers a window radius up to FM_SWEEP_TILE)
 * is not warped and holds -1. */
__kernel void sweep_warp(__global const float* restrict rays, int npix, __global const FmSweepPlane* restrict planes,
                         int plane, __global const FmCamera* restrict cams, __global const FmViewPose* restrict poses,
                         int views, __global const float* restrict images, __global const int* restrict offsets,
                         __global const uchar* restrict needed, int width, int tiles_x, int tiles_y,
                         __global float* restrict warped) {
  int pix = get_global_id(0);
  int y = pix / width;
  int x = pix - y * width;
  if (!needed[((size_t)plane * tiles_y + y / FM_SWEEP_TILE) * tiles_x + x / FM_SWEEP_TILE]) {
    for (int v = 0; v < FM_SWEEP_VIEWS; ++v) {
      warped[v * npix + pix] = -1.0f;
    }
    return;
  }
  float rx = rays[3 * pix], ry = rays[3 * pix + 1], rz = rays[3 * pix + 2];
  float inv_t = fm_plane_inverse_range(planes[plane], rx, ry, rz);
  for (int v = 0; v < FM_SWEEP_VIEWS; ++v) {
    warped[v * npix + pix] = fm_warp_sample_ray(&cams[v], &poses[v], images + offsets[v], rx, ry, rz, inv_t);
  }
}

/* Adds (sign +1) or removes (sign -1) row y of the window sums of column x. */
inline void sweep_row(__global const float* restrict warped, __global const float* restrict ref, int npix,
                      int width, int height, int x, int y, float sign, float* sw, float* sww, float* swr,
                      float* sv) {
  if (y < 0 || y >= height) {
    return;
  }
  int row = y * width;
  for (int dx = -FM_SWEEP_RADIUS; dx <= FM_SWEEP_RADIUS; ++dx) {
    int i = row + x + dx;
    float r = ref[i];
    for (int v = 0; v < FM_SWEEP_VIEWS; ++v) {
      float w = warped[v * npix + i];
      int ok = w >= 0.0f;
      w = ok ? sign * w : 0.0f;
      sw[v] += w;
      sww[v] += sign * w * w;
      swr[v] += w * r;
      sv[v] += ok ? sign : 0.0f;
    }
  }
}

/* One work item per column x and band of `band` rows. The band is cut at tile
 * rows (tiles of FM_SWEEP_TILE pixels): in a tile where the plane is swept
 * (active[(plane * tiles_y + ty) * tiles_x + tx] != 0) the window sums are
 * started afresh from the rows above it and run down the tile (add the row
 * entering the window, remove the one leaving), so each output costs about
 * two window rows, and a pixel's cost depends only on its own tile's rows:
 * the same whether or not the tiles around it are swept. A tile where the
 * plane is not swept costs nothing and gets FM_COST_INVALID. The costs of the
 * supporting views are aggregated into the cost volume's slice for `plane`. */
__kernel void sweep_cost(__global const float* restrict warped, __global const float* restrict ref,
                         __global const float* restrict ref_mean, __global const float* restrict ref_std,
                         int width, int height, int band, int mode, int k, int plane,
                         __global const uchar* restrict active, int tiles_x, int tiles_y,
                         __global float* restrict volume) {
  int x = get_global_id(0);
  int y0 = get_global_id(1) * band;
  int y1 = y0 + band < height ? y0 + band : height;
  int npix = width * height;
  __global float* out = volume + (size_t)plane * (size_t)npix;
  const int inside = x >= FM_SWEEP_RADIUS && x < width - FM_SWEEP_RADIUS;
  const float n = (float)((2 * FM_SWEEP_RADIUS + 1) * (2 * FM_SWEEP_RADIUS + 1));
  float sw[FM_SWEEP_VIEWS], sww[FM_SWEEP_VIEWS], swr[FM_SWEEP_VIEWS], sv[FM_SWEEP_VIEWS],
      costs[FM_SWEEP_VIEWS];
  for (int ty = y0 / FM_SWEEP_TILE; ty <= (y1 - 1) / FM_SWEEP_TILE; ++ty) {
    int ya = ty * FM_SWEEP_TILE > y0 ? ty * FM_SWEEP_TILE : y0;
    int yb = (ty + 1) * FM_SWEEP_TILE < y1 ? (ty + 1) * FM_SWEEP_TILE : y1;
    int on = active[((size_t)plane * tiles_y + ty) * tiles_x + x / FM_SWEEP_TILE];
    if (!on || !inside) {
      for (int y = ya; y < yb; ++y) {
        out[y * width + x] = FM_COST_INVALID;
      }
      continue;
    }
    for (int v = 0; v < FM_SWEEP_VIEWS; ++v) {
      sw[v] = sww[v] = swr[v] = sv[v] = 0.0f;
    }
    for (int y = ya - FM_SWEEP_RADIUS; y < ya + FM_SWEEP_RADIUS; ++y) {
      sweep_row(warped, ref, npix, width, height, x, y, 1.0f, sw, sww, swr, sv);
    }
    for (int y = ya; y < yb; ++y) {
      sweep_row(warped, ref, npix, width, height, x, y + FM_SWEEP_RADIUS, 1.0f, sw, sww, swr, sv);
      int i = y * width + x;
      float mean_r = ref_mean[i], std_r = ref_std[i];
      for (int v = 0; v < FM_SWEEP_VIEWS; ++v) {
        costs[v] = sv[v] == n ? fm_zncc_cost(n, sw[v], sww[v], swr[v], mean_r, std_r) : FM_COST_INVALID;
      }
      out[i] = fm_aggregate(costs, FM_SWEEP_VIEWS, mode, k);
      sweep_row(warped, ref, npix, width, height, x, y - FM_SWEEP_RADIUS, -1.0f, sw, sww, swr, sv);
    }
  }
}

/* Best plane of every pixel: range (NaN if none), best cost, uniqueness ratio. */
__kernel void sweep_select(__global const float* restrict volume, int npix, __global const FmSweepPlane* restrict planes,
                           int n_planes, __global const float* restrict rays, int subpixel,
                           __global float* restrict range, __global float* restrict cost, __global float* restrict ratio) {
  int pix = get_global_id(0);
  float t, c, q;
  if (fm_select_plane(volume + pix, npix, planes, n_planes, rays[3 * pix], rays[3 * pix + 1],
                      rays[3 * pix + 2], subpixel, &t, &c, &q)) {
    range[pix] = t;
    cost[pix] = c;
    ratio[pix] = q;
  } else {
    range[pix] = NAN;
    cost[pix] = NAN;
    ratio[pix] = NAN;
  }
}
