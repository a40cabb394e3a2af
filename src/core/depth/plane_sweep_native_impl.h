// The native CPU plane sweep's loops (see plane_sweep_native.cpp). No include
// guard on purpose: plane_sweep_native.cpp includes this file once per
// instruction set, inside a namespace of its own (native_generic,
// native_avx2), with the target set by a pragma around the include. The
// per-pixel maths are the shared functions of plane_sweep_shared.h and
// camera_model_shared.h (the OpenCL kernels call the same ones); what is here
// is only the loop structure: rows of contiguous floats that the compiler
// vectorizes.

// Per-thread scratch memory, grown on demand.
struct Scratch {
  std::vector<float> warped, p0, p1, p2, p3, t3;  // one row each
  std::vector<uint16_t> quad;        // bilinear samples of a row: 4 pixels each
  std::vector<float> ax, ay;
  std::vector<int> i00, inside;
  std::vector<float> cb, lo, hi, second, t_best;  // plane selection, per band pixel
  std::vector<int> best, prev, next;
  std::vector<float> h0, h1, h2, h3;          // horizontal window sums, (band + 2r) rows
  std::vector<float> vcost;                   // per-view costs, views x band rows (best-k)
  std::vector<float> agg_sum;                 // mean aggregation: sums and counts per band pixel
  std::vector<int> agg_n;
  std::vector<float> volume;                  // cost volume of the band, planes x band rows
  std::vector<std::vector<std::pair<int, int>>> tile_runs;  // per plane and tile row of the band: swept columns
  std::vector<std::pair<int, int>> row_runs;  // a warped row's columns (the tile runs widened by r)
};

// The four pixels of every bilinear sample of a row, from the view's quad
// image (NativeLevel::quads: for each pixel, the pixel and its right, lower
// and lower-right neighbours, clamped at the border as fm_bilinear_setup's
// steps are, as 16-bit units, kQuadMasked where self-masked): one 8-byte load
// per sample, and a quarter of the float image's cache footprint. Scalar on
// purpose: on CPUs plain loads beat gather instructions.
__attribute__((optimize("no-tree-vectorize"))) inline void loadQuads(const uint16_t* __restrict quads,
                                                                   const int* __restrict i00, int w,
                                                                   uint16_t* __restrict out) {
  for (int x = 0; x < w; ++x) std::memcpy(out + 4 * x, quads + 4 * static_cast<size_t>(i00[x]), 8);
}

// A quad image unit back to the sweep's intensity: [0, 1], -1 where masked.
FM_NATIVE_INLINE float quadValue(uint16_t q) {
  return q == kQuadMasked ? -1.0f : static_cast<float>(q) * (1.0f / kQuadScale);
}

// The view's intensity at the plane point of every reference pixel of a row
// (-1 where unusable): fm_warp_sample_ray of the shared header, cut into three
// loops (project and set up the samples; load; blend) so that the first and
// last vectorize. The camera model is a template argument so that its
// dispatch folds away. Returns whether any sample of the row is usable.
template <int MODEL>
FM_NATIVE_INLINE bool warpRowT(const float* __restrict rx, const float* __restrict ry, const float* __restrict rz,
                               int w, FmSweepPlane plane, FmCameraT<float> cam, FmViewPose pose,
                               const uint16_t* __restrict quads, float* __restrict out, Scratch* s) {
  cam.model = MODEL;
  int hits = 0;
  for (int x = 0; x < w; ++x) hits += fm_plane_inverse_range(plane, rx[x], ry[x], rz[x]) > 0.0f;
  if (hits == 0) {
    for (int x = 0; x < w; ++x) out[x] = -1.0f;
    return false;
  }
  const int width = cam.width, height = cam.height;
  int* __restrict i00 = s->i00.data();
  int* __restrict inside = s->inside.data();
  float* __restrict ax = s->ax.data();
  float* __restrict ay = s->ay.data();
#pragma omp simd
  for (int x = 0; x < w; ++x) {
    const float inv_t = fm_plane_inverse_range(plane, rx[x], ry[x], rz[x]);
    float u, v;
    const int ok = fm_warp_project_ray(&cam, &pose, rx[x], ry[x], rz[x], inv_t, &u, &v);
    int a, b, c;
    float e, f;
    inside[x] = fm_bilinear_setup(width, height, ok ? u : -1.0f, ok ? v : -1.0f, &a, &b, &c, &e, &f);
    i00[x] = a;  // the steps b, c are in the quad image already
    (void)b;
    (void)c;
    ax[x] = e;
    ay[x] = f;
  }
  uint16_t* __restrict q = s->quad.data();
  // Only the span of the row that lands inside the view is loaded and blended
  // (a side camera sees part of the reference's rows).
  int first = 0, last = w - 1;
  while (first < w && !inside[first]) ++first;
  while (last > first && !inside[last]) --last;
  if (first == w) {
    for (int x = 0; x < w; ++x) out[x] = -1.0f;
    return false;
  }
  const int span = last - first + 1;
  loadQuads(quads, i00 + first, span, q);
  for (int x = 0; x < first; ++x) out[x] = -1.0f;
  float* __restrict o = out + first;
  for (int x = 0; x < span; ++x) {
    o[x] = fm_bilinear_blend(inside[first + x], quadValue(q[4 * x]), quadValue(q[4 * x + 1]),
                             quadValue(q[4 * x + 2]), quadValue(q[4 * x + 3]), ax[first + x], ay[first + x]);
  }
  for (int x = last + 1; x < w; ++x) out[x] = -1.0f;
  return true;
}

inline bool warpRow(const float* rx, const float* ry, const float* rz, int w, const FmSweepPlane& plane,
                    const FmCameraT<float>& cam, const FmViewPose& pose, const uint16_t* quads, float* out,
                    Scratch* s) {
  switch (cam.model) {
    case FM_MODEL_UNIFIED: return warpRowT<FM_MODEL_UNIFIED>(rx, ry, rz, w, plane, cam, pose, quads, out, s);
    case FM_MODEL_PINHOLE: return warpRowT<FM_MODEL_PINHOLE>(rx, ry, rz, w, plane, cam, pose, quads, out, s);
    case FM_MODEL_DOUBLE_SPHERE:
      return warpRowT<FM_MODEL_DOUBLE_SPHERE>(rx, ry, rz, w, plane, cam, pose, quads, out, s);
    case FM_MODEL_KANNALA_BRANDT:
      return warpRowT<FM_MODEL_KANNALA_BRANDT>(rx, ry, rz, w, plane, cam, pose, quads, out, s);
    default:
      for (int x = 0; x < w; ++x) out[x] = -1.0f;
      return false;
  }
}

// h[x] = sum of p[x - r .. x + r] for x in [r, w - r), 0 elsewhere (a window
// leaving the row never counts as complete). The radius is a template
// argument: the taps unroll and each sum stays in a register while the pixel
// loop vectorizes.
template <int R>
FM_NATIVE_INLINE void boxRowT(const float* __restrict p, float* __restrict h, float* __restrict t, int w) {
  // The 2R+1 taps as blocks of three (t[x] = p[x-1] + p[x] + p[x+1]) and the
  // remaining one or two: half the additions of a plain sum.
  constexpr int kTaps = 2 * R + 1, kBlocks = kTaps / 3, kRest = kTaps % 3;
  for (int x = 1; x < w - 1; ++x) t[x] = p[x - 1] + p[x] + p[x + 1];
  for (int x = 0; x < R && x < w; ++x) h[x] = 0.0f;
  for (int x = R; x < w - R; ++x) {
    float sum = 0.0f;
    for (int k = 0; k < kBlocks; ++k) sum += t[x - R + 1 + 3 * k];
    for (int j = 0; j < kRest; ++j) sum += p[x - R + 3 * kBlocks + j];
    h[x] = sum;
  }
  for (int x = std::max(R, w - R); x < w; ++x) h[x] = 0.0f;
}

inline void boxRow(const float* __restrict p, float* __restrict h, float* __restrict t, int w, int r) {
  switch (r) {
    case 1: boxRowT<1>(p, h, t, w); return;
    case 2: boxRowT<2>(p, h, t, w); return;
    case 3: boxRowT<3>(p, h, t, w); return;
    case 4: boxRowT<4>(p, h, t, w); return;
    case 5: boxRowT<5>(p, h, t, w); return;
    case 6: boxRowT<6>(p, h, t, w); return;
    case 7: boxRowT<7>(p, h, t, w); return;
    default:
      for (int x = 0; x < w; ++x) h[x] = 0.0f;
      for (int d = -r; d <= r; ++d) {
        for (int x = r; x < w - r; ++x) h[x] += p[x + d];
      }
  }
}

// Horizontal window sums of one warped row: W, W^2, W R (over usable
// samples) and the count of usable samples.
inline void rowSums(const float* __restrict warped, const float* __restrict ref, int w, int r, Scratch* s,
                    float* __restrict h0, float* __restrict h1, float* __restrict h2, float* __restrict h3) {
  float* __restrict p0 = s->p0.data();
  float* __restrict p1 = s->p1.data();
  float* __restrict p2 = s->p2.data();
  float* __restrict p3 = s->p3.data();
  for (int x = 0; x < w; ++x) {
    const float q = warped[x];
    const int ok = q >= 0.0f;
    const float a = ok ? q : 0.0f;
    p0[x] = a;
    p1[x] = a * a;
    p2[x] = a * ref[x];
    p3[x] = ok ? 1.0f : 0.0f;
  }
  float* __restrict t = s->t3.data();
  boxRow(p0, h0, t, w, r);
  boxRow(p1, h1, t, w, r);
  boxRow(p2, h2, t, w, r);
  boxRow(p3, h3, t, w, r);
}

// out[x] = sum of rows 0 .. 2r of a (rows `stride` floats apart) for x in
// [0, len), the rows' count a template argument as in boxRowT.
template <int R>
FM_NATIVE_INLINE void boxColumnT(const float* __restrict a, float* __restrict out, int len, size_t stride) {
  for (int x = 0; x < len; ++x) {
    float sum = 0.0f;
    for (int dy = 0; dy <= 2 * R; ++dy) sum += a[dy * stride + x];
    out[x] = sum;
  }
}

inline void boxColumn(const float* __restrict a, float* __restrict out, int len, size_t stride, int r) {
  switch (r) {
    case 1: boxColumnT<1>(a, out, len, stride); return;
    case 2: boxColumnT<2>(a, out, len, stride); return;
    case 3: boxColumnT<3>(a, out, len, stride); return;
    case 4: boxColumnT<4>(a, out, len, stride); return;
    case 5: boxColumnT<5>(a, out, len, stride); return;
    case 6: boxColumnT<6>(a, out, len, stride); return;
    case 7: boxColumnT<7>(a, out, len, stride); return;
    default:
      for (int x = 0; x < len; ++x) out[x] = a[x];
      for (int dy = 1; dy <= 2 * r; ++dy) {
        const float* __restrict row = a + dy * stride;
        for (int x = 0; x < len; ++x) out[x] += row[x];
      }
  }
}

// s[x] += add[x] - sub[x]: the vertical window moved down one row.
inline void slideColumn(float* __restrict sum, const float* __restrict add, const float* __restrict sub, int len) {
  for (int x = 0; x < len; ++x) sum[x] += add[x] - sub[x];
}

// Vertical window sums of the horizontal sums for output row `j` of the band
// (rows j .. j + 2r of the band's buffers, w floats a row), columns
// [a, a + len): summed afresh when `fresh` (the band's first row and the
// first row of every tile row, so that the sums do not depend on which
// columns the rows before were swept at), else slid down a row from row j - 1
// (sums of at most FM_SWEEP_TILE + 2r rows: float drift stays far under the
// cost tolerance; the usable count stays exact), and the ZNCC cost of those
// pixels (cost, mean and stdev point at column 0 of the row).
inline void costRun(const Scratch& s, int w, int r, int j, int a, int len, bool fresh, const float* __restrict mean,
                    const float* __restrict stdev, float* __restrict cost, Scratch* tmp) {
  float* __restrict s0 = tmp->p0.data() + a;
  float* __restrict s1 = tmp->p1.data() + a;
  float* __restrict s2 = tmp->p2.data() + a;
  float* __restrict s3 = tmp->p3.data() + a;
  const size_t stride = static_cast<size_t>(w);
  if (fresh) {
    const size_t o = static_cast<size_t>(j) * w + a;
    boxColumn(s.h0.data() + o, s0, len, stride, r);
    boxColumn(s.h1.data() + o, s1, len, stride, r);
    boxColumn(s.h2.data() + o, s2, len, stride, r);
    boxColumn(s.h3.data() + o, s3, len, stride, r);
  } else {
    const size_t in = static_cast<size_t>(j + 2 * r) * w + a, out = static_cast<size_t>(j - 1) * w + a;
    slideColumn(s0, s.h0.data() + in, s.h0.data() + out, len);
    slideColumn(s1, s.h1.data() + in, s.h1.data() + out, len);
    slideColumn(s2, s.h2.data() + in, s.h2.data() + out, len);
    slideColumn(s3, s.h3.data() + in, s.h3.data() + out, len);
  }
  const float n = static_cast<float>((2 * r + 1) * (2 * r + 1));
  mean += a;
  stdev += a;
  cost += a;
  for (int x = 0; x < len; ++x) {
    const float c = fm_zncc_cost(n, s0[x], s1[x], s2[x], mean[x], stdev[x]);
    cost[x] = s3[x] == n ? c : FM_COST_INVALID;
  }
}

// Column runs [first, second) of a list, merged where they touch or overlap.
using Runs = std::vector<std::pair<int, int>>;
inline void mergeRuns(Runs* runs) {
  if (runs->size() < 2) return;
  std::sort(runs->begin(), runs->end());
  size_t k = 0;
  for (size_t i = 1; i < runs->size(); ++i) {
    if ((*runs)[i].first <= (*runs)[k].second) {
      (*runs)[k].second = std::max((*runs)[k].second, (*runs)[i].second);
    } else {
      (*runs)[++k] = (*runs)[i];
    }
  }
  runs->resize(k + 1);
}

// The columns of tile row `ty` where plane p is swept (L.active; all of them
// without it), as merged runs.
inline void tileRowRuns(const NativeLevel& L, int p, int ty, Runs* runs) {
  runs->clear();
  if (!L.active) {
    runs->emplace_back(0, L.w);
    return;
  }
  const uint8_t* a = L.active + (static_cast<size_t>(p) * L.tiles_y + ty) * L.tiles_x;
  for (int tx = 0; tx < L.tiles_x; ++tx) {
    if (!a[tx]) continue;
    const int x0 = tx * FM_SWEEP_TILE, x1 = std::min(L.w, x0 + FM_SWEEP_TILE);
    if (!runs->empty() && runs->back().second == x0) {
      runs->back().second = x1;
    } else {
      runs->emplace_back(x0, x1);
    }
  }
}

// Calls f(i, len) for each run of band pixels [i, i + len) (band-relative
// indices) where plane p is swept: `runs` holds the band's tile rows' runs of
// that plane.
template <class F>
FM_NATIVE_INLINE void forRunPixels(const Runs* runs, int y0, int y1, int w, F f) {
  const int T = FM_SWEEP_TILE;
  for (int y = y0; y < y1; ++y) {
    const size_t row = static_cast<size_t>(y - y0) * w;
    for (const auto& run : runs[y / T - y0 / T]) f(row + run.first, run.second - run.first);
  }
}

// Aggregated cost of each pixel over V views' cost rows (V a compile-time
// count, so the per-pixel loops unroll and the pixel loop vectorizes).
template <int V, int MODE>
FM_NATIVE_INLINE void aggregateT(const float* vcost, size_t stride, int len, int k, float* __restrict out) {
#pragma omp simd
  for (int i = 0; i < len; ++i) {
    float c[V];
    for (int v = 0; v < V; ++v) c[v] = vcost[v * stride + i];
    out[i] = fm_aggregate(c, V, MODE, k);
  }
}

template <int MODE>
inline void aggregateMode(int views, const float* vcost, size_t stride, int len, int k, float* out) {
  switch (views) {
    case 1: aggregateT<1, MODE>(vcost, stride, len, k, out); break;
    case 2: aggregateT<2, MODE>(vcost, stride, len, k, out); break;
    case 3: aggregateT<3, MODE>(vcost, stride, len, k, out); break;
    case 4: aggregateT<4, MODE>(vcost, stride, len, k, out); break;
    case 5: aggregateT<5, MODE>(vcost, stride, len, k, out); break;
    case 6: aggregateT<6, MODE>(vcost, stride, len, k, out); break;
    case 7: aggregateT<7, MODE>(vcost, stride, len, k, out); break;
    default: aggregateT<FM_SWEEP_MAX_VIEWS, MODE>(vcost, stride, len, k, out); break;
  }
}

// Aggregated cost of each pixel over the views' cost rows; the view count and
// the mode are template arguments, so the per-pixel loops unroll and the
// mode's branch folds away.
inline void aggregate(int views, const float* vcost, size_t stride, int len, int mode, int k, float* out) {
  if (mode == FM_AGGREGATE_BEST_K) {
    aggregateMode<FM_AGGREGATE_BEST_K>(views, vcost, stride, len, k, out);
  } else {
    aggregateMode<FM_AGGREGATE_AVERAGE>(views, vcost, stride, len, k, out);
  }
}

inline void selectBand(const NativeLevel& L, int y0, int y1, size_t band_pix, Scratch* s);

// One band of output rows [y0, y1): the band's cost volume, then the best
// plane of each of its pixels. Per plane, only the tiles L.active marks are
// swept (cost FM_COST_INVALID elsewhere): their columns in each tile row, the
// warped rows within r of them, widened by r for the windows.
inline void sweepBand(const NativeLevel& L, int y0, int y1, Scratch* s) {
  const int w = L.w, h = L.h, r = L.r;
  const int rows = y1 - y0;               // output rows
  const int wrows = rows + 2 * r;         // warped rows, y0 - r .. y1 + r - 1
  const size_t band_pix = static_cast<size_t>(rows) * w;
  auto grow = [](std::vector<float>& v, size_t n) {
    if (v.size() < n) v.resize(n);
  };
  for (auto* v : {&s->warped, &s->p0, &s->p1, &s->p2, &s->p3, &s->t3, &s->ax, &s->ay}) grow(*v, w);
  if (s->quad.size() < 4 * static_cast<size_t>(w)) s->quad.resize(4 * static_cast<size_t>(w));
  for (auto* v : {&s->i00, &s->inside}) {
    if (v->size() < static_cast<size_t>(w)) v->resize(w);
  }
  for (auto* v : {&s->h0, &s->h1, &s->h2, &s->h3}) grow(*v, static_cast<size_t>(wrows) * w);
  // Mean aggregation (the default) sums the views' costs as they come; best-k
  // keeps every view's costs for fm_aggregate.
  const bool mean_mode = L.mode != FM_AGGREGATE_BEST_K;
  grow(s->vcost, band_pix * (mean_mode ? 1 : L.views));
  grow(s->agg_sum, band_pix);
  if (s->agg_n.size() < band_pix) s->agg_n.resize(band_pix);
  float* __restrict agg_sum = s->agg_sum.data();
  int* __restrict agg_n = s->agg_n.data();
  grow(s->volume, band_pix * L.n_planes);
  Scratch tmp;  // row sums of costRun (small; separate from the warp's rows)
  tmp.p0.resize(w);
  tmp.p1.resize(w);
  tmp.p2.resize(w);
  tmp.p3.resize(w);
  const int T = FM_SWEEP_TILE;
  const int ty0 = y0 / T, n_tile_rows = (y1 - 1) / T - ty0 + 1;
  if (s->tile_runs.size() < static_cast<size_t>(L.n_planes) * n_tile_rows) {
    s->tile_runs.resize(static_cast<size_t>(L.n_planes) * n_tile_rows);
  }
  Runs& row_runs = s->row_runs;

  for (int p = 0; p < L.n_planes; ++p) {
    float* vol = s->volume.data() + p * band_pix;
    Runs* runs = s->tile_runs.data() + static_cast<size_t>(p) * n_tile_rows;
    bool swept = false;
    for (int t = 0; t < n_tile_rows; ++t) {
      tileRowRuns(L, p, ty0 + t, &runs[t]);
      swept = swept || !runs[t].empty();
    }
    bool any = false;
    for (int v = 0; swept && v < L.views; ++v) {
      bool view_hit = false;
      for (int j = 0; j < wrows; ++j) {
        const int y = y0 - r + j;
        // The tile rows of the output rows this warped row serves, their
        // runs widened by the window.
        const int ta = (std::max(y0, y - r) / T) - ty0, tb = (std::min(y1 - 1, y + r) / T) - ty0;
        row_runs.clear();
        for (int t = ta; t <= tb; ++t) {
          for (const auto& run : runs[t]) row_runs.emplace_back(std::max(0, run.first - r), std::min(w, run.second + r));
        }
        mergeRuns(&row_runs);
        const size_t o = static_cast<size_t>(j) * w;
        for (const auto& run : row_runs) {
          const int a = run.first, len = run.second - run.first;
          float *h0 = s->h0.data() + o + a, *h1 = s->h1.data() + o + a, *h2 = s->h2.data() + o + a,
                *h3 = s->h3.data() + o + a;
          bool hit = false;
          if (y >= 0 && y < h) {
            const size_t ro = static_cast<size_t>(y) * w + a;
            hit = warpRow(L.rx + ro, L.ry + ro, L.rz + ro, len, L.planes[p], L.cams[v], L.poses[v], L.quads[v],
                          s->warped.data(), s);
          }
          if (hit) {
            rowSums(s->warped.data(), L.ref + static_cast<size_t>(y) * w + a, len, r, s, h0, h1, h2, h3);
            view_hit = true;
          } else {
            for (int x = 0; x < len; ++x) h0[x] = h1[x] = h2[x] = h3[x] = 0.0f;
          }
        }
      }
      float* vc = s->vcost.data() + (mean_mode ? 0 : v * band_pix);
      if (!mean_mode) {
        forRunPixels(runs, y0, y1, w, [&](size_t i, int len) {
          for (int x = 0; x < len; ++x) vc[i + x] = FM_COST_INVALID;
        });
      }
      if (!view_hit) continue;  // adds nothing to a mean
      if (mean_mode && !any) {  // the first view with costs: start the sums
        forRunPixels(runs, y0, y1, w, [&](size_t i, int len) {
          for (int x = 0; x < len; ++x) {
            agg_sum[i + x] = 0.0f;
            agg_n[i + x] = 0;
          }
        });
      }
      any = true;
      for (int j = 0; j < rows; ++j) {
        const int y = y0 + j;
        const size_t ro = static_cast<size_t>(y) * w;
        const bool fresh = j == 0 || y % T == 0;
        float* __restrict c = vc + static_cast<size_t>(j) * w;
        for (const auto& run : runs[y / T - ty0]) {
          const int a = run.first, len = run.second - run.first;
          costRun(*s, w, r, j, a, len, fresh, L.mean + ro, L.stdev + ro, c, &tmp);
          if (mean_mode) {  // fm_aggregate's mean, one view at a time
            float* __restrict sum = agg_sum + static_cast<size_t>(j) * w;
            int* __restrict n = agg_n + static_cast<size_t>(j) * w;
            for (int x = a; x < a + len; ++x) fm_aggregate_add(c[x], &sum[x], &n[x]);
          }
        }
      }
    }
    // The plane's costs where it is swept; elsewhere the volume is not read
    // (selectBand goes by the same runs).
    if (!any) {
      forRunPixels(runs, y0, y1, w, [&](size_t i, int len) {
        for (int x = 0; x < len; ++x) vol[i + x] = FM_COST_INVALID;
      });
      continue;
    }
    if (mean_mode) {
      forRunPixels(runs, y0, y1, w, [&](size_t i, int len) {
        for (int x = 0; x < len; ++x) vol[i + x] = fm_aggregate_mean(agg_sum[i + x], agg_n[i + x]);
      });
    } else {
      forRunPixels(runs, y0, y1, w, [&](size_t i, int len) {
        aggregate(L.views, s->vcost.data() + i, band_pix, len, L.mode, L.k, vol + i);
      });
    }
  }

  selectBand(L, y0, y1, band_pix, s);
}

// Winner takes all for the pixels of a band: the steps of fm_select_plane
// (shared header), run plane by plane over the band's pixels where the plane
// was swept (sweepBand's runs; a plane not swept at a pixel has no cost
// there) so that the two passes over the planes vectorize.
inline void selectBand(const NativeLevel& L, int y0, int y1, size_t band_pix, Scratch* s) {
  const size_t first = static_cast<size_t>(y0) * L.w;
  const int w = L.w, T = FM_SWEEP_TILE;
  const int n_tile_rows = (y1 - 1) / T - y0 / T + 1;
  const float* __restrict rx = L.rx + first;
  const float* __restrict ry = L.ry + first;
  const float* __restrict rz = L.rz + first;
  for (auto* v : {&s->cb, &s->lo, &s->hi, &s->second, &s->t_best}) {
    if (v->size() < band_pix) v->resize(band_pix);
  }
  for (auto* v : {&s->best, &s->prev, &s->next}) {
    if (v->size() < band_pix) v->resize(band_pix);
  }
  float* __restrict cb = s->cb.data();
  int* __restrict best = s->best.data();
  for (size_t i = 0; i < band_pix; ++i) {
    cb[i] = FM_COST_INVALID;
    best[i] = -1;
  }
  auto runsOf = [&](int j) { return s->tile_runs.data() + static_cast<size_t>(j) * n_tile_rows; };
  for (int j = 0; j < L.n_planes; ++j) {
    const float* __restrict vj = s->volume.data() + j * band_pix;
    forRunPixels(runsOf(j), y0, y1, w, [&](size_t i0, int len) {
      for (size_t i = i0; i < i0 + len; ++i) {
        const int better = vj[i] < cb[i];
        cb[i] = better ? vj[i] : cb[i];
        best[i] = better ? j : best[i];
      }
    });
  }
  // Whether plane j was swept at band pixel i.
  auto swept = [&](int j, size_t i) {
    if (!L.active) return true;
    const int y = y0 + static_cast<int>(i / w), x = static_cast<int>(i % w);
    return L.active[(static_cast<size_t>(j) * L.tiles_y + y / T) * L.tiles_x + x / T] != 0;
  };
  int* __restrict prev = s->prev.data();
  int* __restrict next = s->next.data();
  float* __restrict lo = s->lo.data();
  float* __restrict hi = s->hi.data();
  float* __restrict t_best = s->t_best.data();
  float* __restrict second = s->second.data();
  float* volume = s->volume.data();
  for (size_t i = 0; i < band_pix; ++i) {
    second[i] = FM_COST_INVALID;
    if (best[i] < 0) {
      prev[i] = next[i] = -1;
      lo[i] = hi[i] = t_best[i] = 0.0f;
      continue;
    }
    // The refinement reads the best plane's neighbours: no cost where they
    // were not swept.
    for (const int nb : {best[i] - 1, best[i] + 1}) {
      if (nb >= 0 && nb < L.n_planes && !swept(nb, i)) volume[nb * band_pix + i] = FM_COST_INVALID;
    }
    t_best[i] = fm_select_refine(volume + i, static_cast<int>(band_pix), L.planes, L.n_planes, best[i], cb[i], rx[i],
                                 ry[i], rz[i], L.subpixel, &prev[i], &next[i], &lo[i], &hi[i]);
  }
  for (int j = 0; j < L.n_planes; ++j) {
    const float* __restrict vj = s->volume.data() + j * band_pix;
    const FmSweepPlane plane = L.planes[j];
    forRunPixels(runsOf(j), y0, y1, w, [&](size_t i0, int len) {
      for (size_t i = i0; i < i0 + len; ++i) {
        const float t = fm_plane_range(plane, rx[i], ry[i], rz[i]);
        const int take =
            (vj[i] < second[i] ? 1 : 0) & fm_select_second_candidate(j, best[i], prev[i], next[i], t, lo[i], hi[i]);
        second[i] = take ? vj[i] : second[i];
      }
    });
  }
  for (size_t i = 0; i < band_pix; ++i) {
    const bool ok = best[i] >= 0 && t_best[i] > 0.0f;
    L.out_range[first + i] = ok ? t_best[i] : NAN;
    L.out_cost[first + i] = ok ? cb[i] : NAN;
    L.out_ratio[first + i] = ok ? fm_select_ratio(cb[i], second[i]) : NAN;
  }
}

// The whole level: bands of about L.band rows shared out to the OpenMP
// threads, as many bands as a multiple of the thread count so that no thread
// waits for the last band of another.
inline void sweepLevel(const NativeLevel& L) {
  const int threads = std::max(1, omp_get_max_threads());
  int bands = (L.h + L.band - 1) / L.band;
  bands = std::min(L.h, (bands + threads - 1) / threads * threads);
  const int rows = (L.h + bands - 1) / bands;
  bands = (L.h + rows - 1) / rows;
#pragma omp parallel
  {
    Scratch s;
#pragma omp for schedule(dynamic, 1)
    for (int b = 0; b < bands; ++b) {
      sweepBand(L, b * rows, std::min(L.h, (b + 1) * rows), &s);
    }
  }
}
