#include "motionpipe/eval/metrics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

namespace motionpipe::eval {

Result<std::vector<double>> CosineSimilarity(const Embeddings& a, const Embeddings& b) {
  if (a.d != b.d) {
    return InvalidArgument("cosine similarity: embeddings of different sizes (" +
                           std::to_string(a.d) + " and " + std::to_string(b.d) + ")");
  }
  const auto norms = [](const Embeddings& e) {
    std::vector<double> out(static_cast<size_t>(e.n));
    for (int64_t i = 0; i < e.n; ++i) {
      double s = 0;
      for (int64_t k = 0; k < e.d; ++k) s += e.row(i)[k] * e.row(i)[k];
      out[static_cast<size_t>(i)] = std::max(std::sqrt(s), 1e-12);
    }
    return out;
  };
  const auto na = norms(a), nb = norms(b);
  std::vector<double> out(static_cast<size_t>(a.n * b.n));
  for (int64_t i = 0; i < a.n; ++i) {
    for (int64_t j = 0; j < b.n; ++j) {
      double s = 0;
      for (int64_t k = 0; k < a.d; ++k) s += a.row(i)[k] * b.row(j)[k];
      out[static_cast<size_t>(i * b.n + j)] =
          s / (na[static_cast<size_t>(i)] * nb[static_cast<size_t>(j)]);
    }
  }
  return out;
}

std::vector<double> TrueMatchRanks(const std::vector<double>& similarity, int64_t n) {
  std::vector<double> ranks(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) {
    const double own = similarity[static_cast<size_t>(i * n + i)];
    int64_t higher = 0, ties = 0;
    for (int64_t j = 0; j < n; ++j) {
      if (j == i) continue;
      const double s = similarity[static_cast<size_t>(i * n + j)];
      if (s > own)
        ++higher;
      else if (s == own)
        ++ties;
    }
    ranks[static_cast<size_t>(i)] =
        1.0 + static_cast<double>(higher) + 0.5 * static_cast<double>(ties);
  }
  return ranks;
}

RetrievalScores Summarize(const std::vector<double>& ranks) {
  RetrievalScores s;
  s.queries = static_cast<int64_t>(ranks.size());
  if (ranks.empty()) return s;
  for (double r : ranks) {
    s.r1 += r <= 1;
    s.r2 += r <= 2;
    s.r3 += r <= 3;
    s.avg_rank += r;
  }
  const double n = static_cast<double>(ranks.size());
  s.r1 *= 100 / n, s.r2 *= 100 / n, s.r3 *= 100 / n, s.avg_rank /= n;
  return s;
}

Result<RetrievalScores> Retrieval(const Embeddings& queries, const Embeddings& gallery,
                                  int64_t batch, uint64_t seed) {
  if (queries.n != gallery.n) {
    return InvalidArgument("retrieval: " + std::to_string(queries.n) + " queries against " +
                           std::to_string(gallery.n) + " gallery items");
  }
  std::vector<int64_t> order(static_cast<size_t>(queries.n));
  std::iota(order.begin(), order.end(), 0);
  if (batch <= 0)
    batch = queries.n;
  else
    std::shuffle(order.begin(), order.end(), std::mt19937_64(seed));
  std::vector<double> all;
  std::vector<double> rank_of_query(static_cast<size_t>(queries.n),
                                    std::numeric_limits<double>::quiet_NaN());
  for (int64_t start = 0; start + batch <= queries.n; start += batch) {
    Embeddings q{batch, queries.d, {}}, g{batch, gallery.d, {}};
    for (int64_t k = 0; k < batch; ++k) {
      const int64_t i = order[static_cast<size_t>(start + k)];
      q.values.insert(q.values.end(), queries.row(i), queries.row(i) + queries.d);
      g.values.insert(g.values.end(), gallery.row(i), gallery.row(i) + gallery.d);
    }
    MP_ASSIGN_OR_RETURN(const auto similarity, CosineSimilarity(q, g));
    const auto ranks = TrueMatchRanks(similarity, batch);
    all.insert(all.end(), ranks.begin(), ranks.end());
    for (int64_t k = 0; k < batch; ++k)
      rank_of_query[static_cast<size_t>(order[static_cast<size_t>(start + k)])] =
          ranks[static_cast<size_t>(k)];
  }
  RetrievalScores scores = Summarize(all);
  scores.rank_of_query = std::move(rank_of_query);
  return scores;
}

PairedDifference PairedR1Difference(const RetrievalScores& a, const RetrievalScores& b) {
  PairedDifference out;
  const size_t n = std::min(a.rank_of_query.size(), b.rank_of_query.size());
  double sum = 0, squares = 0;
  for (size_t i = 0; i < n; ++i) {
    const double ra = a.rank_of_query[i], rb = b.rank_of_query[i];
    if (std::isnan(ra) || std::isnan(rb)) continue;
    const double d = 100.0 * ((ra <= 1 ? 1.0 : 0.0) - (rb <= 1 ? 1.0 : 0.0));
    sum += d, squares += d * d;
    ++out.queries;
  }
  if (out.queries == 0) return out;
  const double q = static_cast<double>(out.queries);
  out.value = sum / q;
  // The sample standard deviation of the differences over sqrt(queries).
  if (out.queries > 1)
    out.standard_error = std::sqrt(std::max(0.0, (squares - sum * sum / q) / (q - 1)) / q);
  return out;
}

namespace {

double Norm3(const float* a, const float* b, bool horizontal_only = false) {
  const double dx = a[0] - b[0], dy = a[1] - b[1], dz = horizontal_only ? 0.0 : a[2] - b[2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

// cos and sin of a frame's heading: the angle of its hips' axis (left minus right) on the ground
// plane; (1, 0) when `heading` names no hips or they coincide. Rotating by -angle removes it.
void HeadingOf(const float* frame, int joints, const HeadingJoints& heading, double* c, double* s) {
  *c = 1, *s = 0;
  if (heading.left < 0 || heading.right < 0 || heading.left >= joints || heading.right >= joints)
    return;
  const double ax = frame[heading.left * 3] - frame[heading.right * 3],
               ay = frame[heading.left * 3 + 1] - frame[heading.right * 3 + 1];
  const double norm = std::hypot(ax, ay);
  if (norm > 1e-9) *c = ax / norm, *s = ay / norm;
}

// Root-relative joints; with hips given, each frame is also turned about z so that its hips' axis
// (left minus right, on the ground plane) points along +x: the heading is removed.
std::vector<float> Local(const std::vector<float>& x, int64_t frames, int joints,
                         const HeadingJoints& heading) {
  std::vector<float> out(x.begin(), x.begin() + frames * joints * 3);
  for (int64_t t = 0; t < frames; ++t) {
    float* frame = out.data() + t * joints * 3;
    const float* root = x.data() + t * joints * 3;
    double c, s;
    HeadingOf(frame, joints, heading, &c, &s);
    for (int j = 0; j < joints; ++j) {
      const double px = frame[j * 3] - root[0], py = frame[j * 3 + 1] - root[1];
      frame[j * 3] = static_cast<float>(c * px + s * py);
      frame[j * 3 + 1] = static_cast<float>(-s * px + c * py);
      frame[j * 3 + 2] -= root[2];
    }
  }
  return out;
}

Result<int64_t> Frames(const std::vector<float>& a, const std::vector<float>& b, int joints) {
  const int64_t fa = static_cast<int64_t>(a.size()) / (joints * 3),
                fb = static_cast<int64_t>(b.size()) / (joints * 3);
  const int64_t frames = std::min(fa, fb);
  if (frames < 1) return InvalidArgument("APE/AVE: an empty motion");
  return frames;
}

// Per-coordinate variance over time (unbiased) of joint j: 3 values.
std::array<double, 3> Variance(const std::vector<float>& x, int64_t frames, int joints, int j,
                               bool horizontal_only) {
  std::array<double, 3> mean{}, var{};
  for (int64_t t = 0; t < frames; ++t) {
    for (int c = 0; c < 3; ++c)
      mean[static_cast<size_t>(c)] += x[static_cast<size_t>((t * joints + j) * 3 + c)];
  }
  for (auto& m : mean) m /= static_cast<double>(frames);
  for (int64_t t = 0; t < frames; ++t) {
    for (int c = 0; c < 3; ++c) {
      const double d =
          x[static_cast<size_t>((t * joints + j) * 3 + c)] - mean[static_cast<size_t>(c)];
      var[static_cast<size_t>(c)] += d * d;
    }
  }
  for (auto& v : var) v /= static_cast<double>(std::max<int64_t>(1, frames - 1));
  if (horizontal_only) var[2] = 0;
  return var;
}

double VarianceError(const std::vector<float>& a, const std::vector<float>& b, int64_t frames,
                     int joints, int j, bool horizontal_only) {
  const auto va = Variance(a, frames, joints, j, horizontal_only),
             vb = Variance(b, frames, joints, j, horizontal_only);
  double s = 0;
  for (int c = 0; c < 3; ++c)
    s += (va[static_cast<size_t>(c)] - vb[static_cast<size_t>(c)]) *
         (va[static_cast<size_t>(c)] - vb[static_cast<size_t>(c)]);
  return std::sqrt(s);
}

}  // namespace

void Canonicalize(std::vector<float>* joints, int count, const HeadingJoints& heading) {
  if (joints->size() < static_cast<size_t>(count) * 3) return;
  float* x = joints->data();
  const double ox = x[0], oy = x[1];
  double c, s;
  HeadingOf(x, count, heading, &c, &s);
  for (size_t k = 0; k + 2 < joints->size(); k += 3) {
    const double px = x[k] - ox, py = x[k + 1] - oy;
    x[k] = static_cast<float>(c * px + s * py);
    x[k + 1] = static_cast<float>(-s * px + c * py);
  }
}

Result<PositionErrors> AveragePositionalError(const std::vector<float>& generated,
                                              const std::vector<float>& truth, int joints,
                                              const HeadingJoints& heading) {
  MP_ASSIGN_OR_RETURN(const int64_t frames, Frames(generated, truth, joints));
  const auto lg = Local(generated, frames, joints, heading),
             lt = Local(truth, frames, joints, heading);
  PositionErrors e;
  for (int64_t t = 0; t < frames; ++t) {
    const float* g = generated.data() + t * joints * 3;
    const float* r = truth.data() + t * joints * 3;
    e.root += Norm3(g, r);
    e.trajectory += Norm3(g, r, true);
    for (int j = 0; j < joints; ++j) {
      e.mean_global += Norm3(g + 3 * j, r + 3 * j);
      if (j > 0)
        e.mean_local += Norm3(lg.data() + (t * joints + j) * 3, lt.data() + (t * joints + j) * 3);
    }
  }
  const double f = static_cast<double>(frames);
  e.root /= f, e.trajectory /= f, e.mean_global /= f * joints,
      e.mean_local /= f * std::max(1, joints - 1);
  return e;
}

Result<PositionErrors> AverageVarianceError(const std::vector<float>& generated,
                                            const std::vector<float>& truth, int joints,
                                            const HeadingJoints& heading) {
  MP_ASSIGN_OR_RETURN(const int64_t frames, Frames(generated, truth, joints));
  const auto lg = Local(generated, frames, joints, heading),
             lt = Local(truth, frames, joints, heading);
  PositionErrors e;
  e.root = VarianceError(generated, truth, frames, joints, 0, false);
  e.trajectory = VarianceError(generated, truth, frames, joints, 0, true);
  for (int j = 0; j < joints; ++j) {
    e.mean_global += VarianceError(generated, truth, frames, joints, j, false);
    if (j > 0) e.mean_local += VarianceError(lg, lt, frames, joints, j, false);
  }
  e.mean_global /= joints;
  e.mean_local /= std::max(1, joints - 1);
  return e;
}

void SymmetricEigen(std::vector<double> a, int64_t n, std::vector<double>* values,
                    std::vector<double>* vectors) {
  std::vector<double>& v = *vectors;
  v.assign(static_cast<size_t>(n * n), 0.0);
  for (int64_t i = 0; i < n; ++i) v[static_cast<size_t>(i * n + i)] = 1;
  const auto at = [n](std::vector<double>& m, int64_t i, int64_t j) -> double& {
    return m[static_cast<size_t>(i * n + j)];
  };
  for (int sweep = 0; sweep < 100; ++sweep) {
    double off = 0;
    for (int64_t i = 0; i < n; ++i) {
      for (int64_t j = i + 1; j < n; ++j) off += at(a, i, j) * at(a, i, j);
    }
    if (off < 1e-30) break;
    for (int64_t p = 0; p < n; ++p) {
      for (int64_t q = p + 1; q < n; ++q) {
        const double apq = at(a, p, q);
        if (std::abs(apq) < 1e-300) continue;
        const double theta = (at(a, q, q) - at(a, p, p)) / (2 * apq);
        const double t =
            (theta >= 0 ? 1.0 : -1.0) / (std::abs(theta) + std::sqrt(theta * theta + 1));
        const double c = 1 / std::sqrt(t * t + 1), s = t * c;
        for (int64_t k = 0; k < n; ++k) {  // columns p, q
          const double akp = at(a, k, p), akq = at(a, k, q);
          at(a, k, p) = c * akp - s * akq;
          at(a, k, q) = s * akp + c * akq;
        }
        for (int64_t k = 0; k < n; ++k) {  // rows p, q
          const double apk = at(a, p, k), aqk = at(a, q, k);
          at(a, p, k) = c * apk - s * aqk;
          at(a, q, k) = s * apk + c * aqk;
        }
        for (int64_t k = 0; k < n; ++k) {
          const double vkp = at(v, k, p), vkq = at(v, k, q);
          at(v, k, p) = c * vkp - s * vkq;
          at(v, k, q) = s * vkp + c * vkq;
        }
      }
    }
  }
  values->resize(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) (*values)[static_cast<size_t>(i)] = at(a, i, i);
}

namespace {

Status MeanAndCovariance(const Embeddings& x, std::vector<double>* mean, std::vector<double>* cov) {
  if (x.n < 2) return InvalidArgument("FID: need at least 2 embeddings per set");
  mean->assign(static_cast<size_t>(x.d), 0.0);
  for (int64_t i = 0; i < x.n; ++i) {
    for (int64_t k = 0; k < x.d; ++k) (*mean)[static_cast<size_t>(k)] += x.row(i)[k];
  }
  for (auto& m : *mean) m /= static_cast<double>(x.n);
  cov->assign(static_cast<size_t>(x.d * x.d), 0.0);
  for (int64_t i = 0; i < x.n; ++i) {
    for (int64_t a = 0; a < x.d; ++a) {
      const double da = x.row(i)[a] - (*mean)[static_cast<size_t>(a)];
      for (int64_t b = 0; b < x.d; ++b)
        (*cov)[static_cast<size_t>(a * x.d + b)] +=
            da * (x.row(i)[b] - (*mean)[static_cast<size_t>(b)]);
    }
  }
  for (auto& c : *cov) c /= static_cast<double>(x.n - 1);
  return Status::Ok();
}

}  // namespace

Result<double> FrechetDistance(const Embeddings& a, const Embeddings& b) {
  if (a.d != b.d) return InvalidArgument("FID: embeddings of different sizes");
  const int64_t d = a.d;
  std::vector<double> ma, ca, mb, cb;
  MP_RETURN_IF_ERROR(MeanAndCovariance(a, &ma, &ca));
  MP_RETURN_IF_ERROR(MeanAndCovariance(b, &mb, &cb));
  double mean_term = 0, trace = 0;
  for (int64_t k = 0; k < d; ++k) {
    mean_term += (ma[static_cast<size_t>(k)] - mb[static_cast<size_t>(k)]) *
                 (ma[static_cast<size_t>(k)] - mb[static_cast<size_t>(k)]);
    trace += ca[static_cast<size_t>(k * d + k)] + cb[static_cast<size_t>(k * d + k)];
  }
  // Tr((Ca Cb)^1/2) = Tr((Ca^1/2 Cb Ca^1/2)^1/2), the inner matrix symmetric positive
  // semi-definite.
  std::vector<double> values, vectors;
  SymmetricEigen(ca, d, &values, &vectors);
  std::vector<double> root(static_cast<size_t>(d * d), 0.0);
  for (int64_t i = 0; i < d; ++i) {
    for (int64_t j = 0; j < d; ++j) {
      double s = 0;
      for (int64_t k = 0; k < d; ++k) {
        s += vectors[static_cast<size_t>(i * d + k)] *
             std::sqrt(std::max(0.0, values[static_cast<size_t>(k)])) *
             vectors[static_cast<size_t>(j * d + k)];
      }
      root[static_cast<size_t>(i * d + j)] = s;
    }
  }
  std::vector<double> tmp(static_cast<size_t>(d * d), 0.0), inner(static_cast<size_t>(d * d), 0.0);
  for (int64_t i = 0; i < d; ++i) {
    for (int64_t j = 0; j < d; ++j) {
      double s = 0;
      for (int64_t k = 0; k < d; ++k)
        s += root[static_cast<size_t>(i * d + k)] * cb[static_cast<size_t>(k * d + j)];
      tmp[static_cast<size_t>(i * d + j)] = s;
    }
  }
  for (int64_t i = 0; i < d; ++i) {
    for (int64_t j = 0; j < d; ++j) {
      double s = 0;
      for (int64_t k = 0; k < d; ++k)
        s += tmp[static_cast<size_t>(i * d + k)] * root[static_cast<size_t>(k * d + j)];
      inner[static_cast<size_t>(i * d + j)] = s;
    }
  }
  for (int64_t i = 0; i < d; ++i) {  // symmetrise against rounding
    for (int64_t j = i + 1; j < d; ++j) {
      const double m =
          0.5 * (inner[static_cast<size_t>(i * d + j)] + inner[static_cast<size_t>(j * d + i)]);
      inner[static_cast<size_t>(i * d + j)] = inner[static_cast<size_t>(j * d + i)] = m;
    }
  }
  SymmetricEigen(inner, d, &values, &vectors);
  double cross = 0;
  for (double v : values) cross += std::sqrt(std::max(0.0, v));
  return std::max(0.0, mean_term + trace - 2 * cross);
}

double Diversity(const Embeddings& x, int64_t pairs, uint64_t seed) {
  if (x.n < 2 || pairs < 1) return 0;
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int64_t> pick(0, x.n - 1);
  double total = 0;
  for (int64_t p = 0; p < pairs; ++p) {
    const int64_t i = pick(rng);
    int64_t j = pick(rng);
    while (j == i) j = pick(rng);
    double s = 0;
    for (int64_t k = 0; k < x.d; ++k)
      s += (x.row(i)[k] - x.row(j)[k]) * (x.row(i)[k] - x.row(j)[k]);
    total += std::sqrt(s);
  }
  return total / static_cast<double>(pairs);
}

double Multimodality(const Embeddings& x, const std::vector<std::vector<int64_t>>& groups) {
  double total = 0;
  int64_t count = 0;
  for (const auto& g : groups) {
    for (size_t a = 0; a < g.size(); ++a) {
      for (size_t b = a + 1; b < g.size(); ++b) {
        double s = 0;
        for (int64_t k = 0; k < x.d; ++k)
          s += (x.row(g[a])[k] - x.row(g[b])[k]) * (x.row(g[a])[k] - x.row(g[b])[k]);
        total += std::sqrt(s);
        ++count;
      }
    }
  }
  return count ? total / static_cast<double>(count) : 0;
}

}  // namespace motionpipe::eval
