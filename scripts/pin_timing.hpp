// Timing and state helpers shared by scripts/pin_kin_bench.cpp and scripts/pin_loop_bench.cpp
// (the method of ../shared/peer/pin_bench.cpp): pre-generated states used round robin, a
// warm-up, batches of K calls for short ones, median/p10/p90 per call; the finite sampling
// bounds of the random configurations. Include it after the Pinocchio headers.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

using namespace pinocchio;
typedef std::chrono::steady_clock Clock;

static volatile double g_sink = 0.0;

struct Stats
{
  double med, p10, p90;
  size_t batch, nsamples;
};

static double ns_since(const Clock::time_point & t0, const Clock::time_point & t1)
{
  return std::chrono::duration<double, std::nano>(t1 - t0).count();
}

static double quantile(std::vector<double> v, double q)
{
  std::sort(v.begin(), v.end());
  const double pos = q * (double)(v.size() - 1);
  const size_t lo = (size_t)std::floor(pos), hi = (size_t)std::ceil(pos);
  return v[lo] + (pos - (double)lo) * (v[hi] - v[lo]);
}

static Stats summarize(const std::vector<double> & ns_per_call, size_t batch)
{
  Stats s;
  s.med = quantile(ns_per_call, 0.5) * 1e-3;
  s.p10 = quantile(ns_per_call, 0.1) * 1e-3;
  s.p90 = quantile(ns_per_call, 0.9) * 1e-3;
  s.batch = batch;
  s.nsamples = ns_per_call.size();
  return s;
}

// f(i) runs the algorithm on state i.
static Stats bench(
  const std::function<void(size_t)> & f, size_t nstates, size_t iters, double max_seconds)
{
  size_t idx = 0;
  // warm-up: at least max(200, iters/10) calls and at least 50 ms
  size_t nwarm = 0;
  const size_t min_warm = std::max<size_t>(200, iters / 10);
  const Clock::time_point w0 = Clock::now();
  double warm_ns = 0;
  while (true)
  {
    f(idx);
    idx = (idx + 1) % nstates;
    ++nwarm;
    if (nwarm % 16 == 0 || nwarm >= min_warm)
    {
      warm_ns = ns_since(w0, Clock::now());
      if (nwarm >= min_warm && warm_ns > 5e7)
        break;
      if (warm_ns > 2e9 && nwarm >= 20)
        break; // very slow algorithm
    }
  }
  const double est_ns = warm_ns / (double)nwarm;
  const double target_batch_ns = 10000.0; // 10 us
  size_t K = (size_t)std::ceil(target_batch_ns / std::max(est_ns, 1.0));
  K = std::max<size_t>(1, std::min<size_t>(K, 1000));
  const size_t nbatches_wanted = std::max<size_t>(200, (iters + K - 1) / K);

  std::vector<double> samples;
  samples.reserve(nbatches_wanted);
  const Clock::time_point start = Clock::now();
  for (size_t b = 0; b < nbatches_wanted; ++b)
  {
    const Clock::time_point t0 = Clock::now();
    for (size_t k = 0; k < K; ++k)
    {
      f(idx);
      idx = (idx + 1) % nstates;
    }
    const Clock::time_point t1 = Clock::now();
    samples.push_back(ns_since(t0, t1) / (double)K);
    if (samples.size() >= 200 && ns_since(start, t1) > max_seconds * 1e9)
      break;
  }
  return summarize(samples, K);
}

// pre(i) is run untimed before each timed f(i).
static Stats bench_pre(
  const std::function<void(size_t)> & pre,
  const std::function<void(size_t)> & f,
  size_t nstates,
  size_t iters,
  double max_seconds)
{
  size_t idx = 0;
  const size_t nwarm = std::max<size_t>(200, iters / 10);
  const Clock::time_point w0 = Clock::now();
  for (size_t i = 0; i < nwarm; ++i)
  {
    pre(idx);
    f(idx);
    idx = (idx + 1) % nstates;
    if (ns_since(w0, Clock::now()) > 2e9 && i >= 20)
      break;
  }
  std::vector<double> samples;
  samples.reserve(iters);
  const Clock::time_point start = Clock::now();
  for (size_t it = 0; it < iters; ++it)
  {
    pre(idx);
    const Clock::time_point t0 = Clock::now();
    f(idx);
    const Clock::time_point t1 = Clock::now();
    samples.push_back(ns_since(t0, t1));
    idx = (idx + 1) % nstates;
    if (samples.size() >= 200 && ns_since(start, t1) > max_seconds * 1e9)
      break;
  }
  return summarize(samples, 1);
}

static std::vector<std::string> split(const std::string & s, char sep)
{
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep))
    if (!item.empty())
      out.push_back(item);
  return out;
}

// Finite sampling bounds: URDF limits where meaningful, +-pi for unbounded/absent
// revolute limits, [-1,1] for the free-flyer translation.
static void sampling_bounds(
  const Model & model, bool ff, Eigen::VectorXd & lower, Eigen::VectorXd & upper)
{
  lower = model.lowerPositionLimit;
  upper = model.upperPositionLimit;
  for (Eigen::Index i = 0; i < model.nq; ++i)
  {
    const bool bad = !std::isfinite(lower[i]) || !std::isfinite(upper[i]) || lower[i] < -1e3
                     || upper[i] > 1e3 || !(upper[i] > lower[i]);
    if (bad)
    {
      lower[i] = -M_PI;
      upper[i] = M_PI;
    }
  }
  if (ff)
  {
    const int iq = model.joints[1].idx_q();
    for (int k = 0; k < 3; ++k)
    {
      lower[iq + k] = -1.0;
      upper[iq + k] = 1.0;
    }
    for (int k = 3; k < 7; ++k)
    {
      lower[iq + k] = -1.0;
      upper[iq + k] = 1.0;
    }
  }
}

