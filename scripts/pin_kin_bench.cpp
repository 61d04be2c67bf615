// Pinocchio 4.1.0 (PyPI wheel `pin`) timings of the kinematics that sodyn's `bench` times under
// the same names (src/bin/sodyn/bench.rs), with the method and output line format of
// ../shared/peer/pin_bench.cpp (whose timing/state code is in scripts/pin_timing.hpp): pre-generated
// states round robin, warm-up, batches of K calls for short ones, median/p10/p90 per call.
//
// Usage:
//   pin_kin_bench URDF ff|fixed ITERS --frame NAME [--name N] [--nstates 1000] [--seed 42]
//       [--algos a,b] [--max-seconds 4] [--check] [--state FILE]
//
// Each algorithm is what a Pinocchio user calls for the same output (the fastest documented
// path), Pinocchio's [linear; angular] order against sodyn's [angular; linear]:
//   frame_placement              forwardKinematics(q) + updateFramePlacement(frame)
//   frame_jacobian_{local,world,lwa}
//                                J.setZero() + computeFrameJacobian(q, frame, rf, J) (walks the
//                                frame's support only; the API requires a zeroed J)
//   frame_velocity               forwardKinematics(q, v) + getFrameVelocity(frame, LOCAL)
//   frame_acceleration           forwardKinematics(q, v, a) + getFrameAcceleration(frame, LOCAL)
//   frame_classical_acceleration forwardKinematics(q, v, a) + getFrameClassicalAcceleration(LOCAL)
//   frame_velocity_derivatives[_world]
//                                computeForwardKinematicsDerivatives(q, v, a) +
//                                getFrameVelocityDerivatives(frame, LOCAL|WORLD)
//   frame_acceleration_derivatives[_world]
//                                computeForwardKinematicsDerivatives(q, v, a) +
//                                getFrameAccelerationDerivatives(frame, LOCAL|WORLD); LOCAL
//                                needs v_partial_dq and a_partial_dq zeroed first (the root
//                                joint's columns are otherwise stale and transformed again)
//   com                          centerOfMass(q, computeSubtreeComs = false)
//   com_jacobian                 jacobianCenterOfMass(q, computeSubtreeComs = false)
//   com_velocity_derivatives     centerOfMass(q, v) + getCenterOfMassVelocityDerivatives
//   centroidal_momentum          computeCentroidalMomentum(q, v)
//   centroidal_dynamics_derivatives
//                                computeCentroidalDynamicsDerivatives(q, v, a, 4 outputs)
//   difference                   difference(q0, q1)
//   d_integrate_q, d_integrate_v dIntegrate(q, v, ARG0 | ARG1)
//   d_difference_q0, d_difference_q1
//                                dDifference(q0, q1, ARG0 | ARG1)
// q1 of difference/dDifference is the next state's q. --check prints a checksum (sum of
// absolute values of the outputs) for state 0 per algorithm; --state FILE replaces state 0 by
// "q0(nq) v(nv) a(nv) q1(nq)" read from FILE (Pinocchio's order; q1 becomes state 1's q), so
// the checksums can be compared with sodyn's at the same state (sums of absolute values do not
// depend on the [linear; angular] order).

#include <pinocchio/parsers/urdf.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics-derivatives.hpp>
#include <pinocchio/algorithm/frames-derivatives.hpp>
#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/center-of-mass-derivatives.hpp>
#include <pinocchio/algorithm/centroidal.hpp>
#include <pinocchio/algorithm/centroidal-derivatives.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iostream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "pin_timing.hpp"

static Model load_model(const std::string & urdf_path, bool ff)
{
  Model model;
  if (ff)
    pinocchio::urdf::buildModel(urdf_path, JointModelFreeFlyer(), model);
  else
    pinocchio::urdf::buildModel(urdf_path, model);
  return model;
}


int main(int argc, char ** argv)
{
  if (argc < 4)
  {
    std::cerr << "usage: " << argv[0] << " URDF ff|fixed ITERS --frame NAME [options]\n";
    return 1;
  }
  const std::string urdf = argv[1];
  const std::string base = argv[2];
  if (base != "ff" && base != "fixed")
  {
    std::cerr << "second argument must be ff or fixed\n";
    return 1;
  }
  const bool ff = (base == "ff");
  Model model = load_model(urdf, ff);
  const size_t iters = (size_t)std::atol(argv[3]);
  std::string name;
  {
    std::string stem = urdf.substr(urdf.find_last_of('/') + 1);
    name = stem.substr(0, stem.find_last_of('.'));
  }
  size_t nstates = 1000;
  unsigned seed = 42;
  std::string frame_name;
  std::set<std::string> only;
  double max_seconds = 4.0;
  bool check = false;
  std::string state_file;
  for (int i = 4; i < argc; ++i)
  {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc)
      {
        std::cerr << "missing value for " << a << "\n";
        std::exit(1);
      }
      return std::string(argv[++i]);
    };
    if (a == "--name")
      name = next();
    else if (a == "--nstates")
      nstates = (size_t)std::atol(next().c_str());
    else if (a == "--seed")
      seed = (unsigned)std::atol(next().c_str());
    else if (a == "--frame")
      frame_name = next();
    else if (a == "--algos")
    {
      for (auto & s : split(next(), ','))
        only.insert(s);
    }
    else if (a == "--max-seconds")
      max_seconds = std::atof(next().c_str());
    else if (a == "--check")
      check = true;
    else if (a == "--state")
      state_file = next();
    else
    {
      std::cerr << "unknown option " << a << "\n";
      return 1;
    }
  }
  if (frame_name.empty() || !model.existFrame(frame_name))
  {
    std::cerr << "--frame NAME is required and must name a frame of the model (got \""
              << frame_name << "\")\n";
    return 1;
  }
  const FrameIndex fid = model.getFrameId(frame_name);

  std::srand(seed);
  Eigen::VectorXd lower, upper;
  sampling_bounds(model, ff, lower, upper);
  std::vector<Eigen::VectorXd> qs(nstates), vs(nstates), as(nstates);
  for (size_t i = 0; i < nstates; ++i)
  {
    qs[i] = randomConfiguration(model, lower, upper);
    vs[i] = Eigen::VectorXd::Random(model.nv);
    as[i] = Eigen::VectorXd::Random(model.nv);
  }
  if (!state_file.empty())
  {
    std::ifstream fin(state_file);
    Eigen::VectorXd q1(model.nq);
    for (int k = 0; k < model.nq; ++k)
      fin >> qs[0][k];
    for (int k = 0; k < model.nv; ++k)
      fin >> vs[0][k];
    for (int k = 0; k < model.nv; ++k)
      fin >> as[0][k];
    for (int k = 0; k < model.nq; ++k)
      fin >> q1[k];
    if (!fin || nstates < 2)
    {
      std::cerr << "cannot read --state " << state_file << " (or --nstates < 2)\n";
      return 1;
    }
    qs[1] = q1;
  }
  auto nxt = [&](size_t i) { return (i + 1) % nstates; };

  Data data(model);
  {
    std::vector<double> ov(10000);
    for (auto & x : ov)
    {
      const Clock::time_point t0 = Clock::now();
      const Clock::time_point t1 = Clock::now();
      x = ns_since(t0, t1);
    }
    std::printf(
      "# model=%s urdf=%s base=%s nq=%d nv=%d njoints=%d nstates=%zu seed=%u "
      "timer_overhead_ns=%.1f frame=%s\n",
      name.c_str(), urdf.c_str(), base.c_str(), model.nq, model.nv, model.njoints, nstates, seed,
      quantile(ov, 0.5), frame_name.c_str());
    std::fflush(stdout);
  }
  auto want = [&](const std::string & a) { return only.empty() || only.count(a); };
  auto report = [&](const std::string & algo, const Stats & s) {
    std::printf(
      "model=%s nq=%d nv=%d algo=%s median_us=%.4f p10_us=%.4f p90_us=%.4f batch=%zu "
      "samples=%zu frame=%s\n",
      name.c_str(), model.nq, model.nv, algo.c_str(), s.med, s.p10, s.p90, s.batch, s.nsamples,
      frame_name.c_str());
    std::fflush(stdout);
  };
  auto cs = [](const Eigen::MatrixXd & m) { return m.cwiseAbs().sum(); };
  auto run = [&](const std::string & algo, const std::function<void(size_t)> & f,
                 const std::function<double()> & sum) {
    if (!want(algo))
      return;
    report(algo, bench(f, nstates, iters, max_seconds));
    if (check)
    {
      f(0);
      std::printf("check model=%s algo=%s state0_abs_sum=%.12e\n", name.c_str(), algo.c_str(), sum());
      std::fflush(stdout);
    }
  };

  const int nv = model.nv;
  Data::Matrix6x J(6, nv), d1(6, nv), d2(6, nv), d3(6, nv), d4(6, nv);
  J.setZero(); d1.setZero(); d2.setZero(); d3.setZero(); d4.setZero();
  Data::Matrix3x J3(3, nv);
  J3.setZero();
  Eigen::MatrixXd Jq(nv, nv);
  Jq.setZero();
  Eigen::VectorXd dq(nv);
  Motion mo;

  run("frame_placement",
      [&](size_t i) {
        forwardKinematics(model, data, qs[i]);
        updateFramePlacement(model, data, fid);
      },
      [&] { return cs(data.oMf[fid].toHomogeneousMatrix()); });
  const std::pair<const char *, ReferenceFrame> refs[3] = {
    {"frame_jacobian_local", LOCAL},
    {"frame_jacobian_world", WORLD},
    {"frame_jacobian_lwa", LOCAL_WORLD_ALIGNED}};
  for (const auto & r : refs)
  {
    const ReferenceFrame rf = r.second;
    run(r.first,
        [&](size_t i) {
          J.setZero();
          computeFrameJacobian(model, data, qs[i], fid, rf, J);
        },
        [&] { return cs(J); });
  }
  run("frame_velocity",
      [&](size_t i) {
        forwardKinematics(model, data, qs[i], vs[i]);
        mo = getFrameVelocity(model, data, fid, LOCAL);
      },
      [&] { return cs(mo.toVector()); });
  run("frame_acceleration",
      [&](size_t i) {
        forwardKinematics(model, data, qs[i], vs[i], as[i]);
        mo = getFrameAcceleration(model, data, fid, LOCAL);
      },
      [&] { return cs(mo.toVector()); });
  run("frame_classical_acceleration",
      [&](size_t i) {
        forwardKinematics(model, data, qs[i], vs[i], as[i]);
        mo = getFrameClassicalAcceleration(model, data, fid, LOCAL);
      },
      [&] { return cs(mo.toVector()); });
  const std::pair<const char *, ReferenceFrame> drefs[2] = {{"", LOCAL}, {"_world", WORLD}};
  for (const auto & r : drefs)
  {
    const ReferenceFrame rf = r.second;
    run(std::string("frame_velocity_derivatives") + r.first,
        [&](size_t i) {
          computeForwardKinematicsDerivatives(model, data, qs[i], vs[i], as[i]);
          getFrameVelocityDerivatives(model, data, fid, rf, d1, d2);
        },
        [&] { return cs(d1) + cs(d2); });
    run(std::string("frame_acceleration_derivatives") + r.first,
        [&](size_t i) {
          computeForwardKinematicsDerivatives(model, data, qs[i], vs[i], as[i]);
          if (rf == LOCAL)
          {
            // In LOCAL, the columns of the root joint (parent 0) of v_partial_dq and
            // a_partial_dq are not written by the joint pass but transformed in place by the
            // frame pass: without zeroing they accumulate garbage from call to call.
            d1.setZero();
            d2.setZero();
          }
          getFrameAccelerationDerivatives(model, data, fid, rf, d1, d2, d3, d4);
        },
        [&] { return cs(d2) + cs(d3) + cs(d4); });
  }
  run("com", [&](size_t i) { centerOfMass(model, data, qs[i], false); },
      [&] { return cs(data.com[0]); });
  run("com_jacobian", [&](size_t i) { jacobianCenterOfMass(model, data, qs[i], false); },
      [&] { return cs(data.Jcom); });
  run("com_velocity_derivatives",
      [&](size_t i) {
        centerOfMass(model, data, qs[i], vs[i]);
        getCenterOfMassVelocityDerivatives(model, data, J3);
      },
      [&] { return cs(J3); });
  run("centroidal_momentum",
      [&](size_t i) { computeCentroidalMomentum(model, data, qs[i], vs[i]); },
      [&] { return cs(data.hg.toVector()); });
  run("centroidal_dynamics_derivatives",
      [&](size_t i) {
        computeCentroidalDynamicsDerivatives(model, data, qs[i], vs[i], as[i], d1, d2, d3, d4);
      },
      [&] { return cs(d1) + cs(d2) + cs(d3) + cs(d4); });
  run("difference", [&](size_t i) { difference(model, qs[i], qs[nxt(i)], dq); },
      [&] { return cs(dq); });
  run("d_integrate_q", [&](size_t i) { dIntegrate(model, qs[i], vs[i], Jq, ARG0); },
      [&] { return cs(Jq); });
  run("d_integrate_v", [&](size_t i) { dIntegrate(model, qs[i], vs[i], Jq, ARG1); },
      [&] { return cs(Jq); });
  run("d_difference_q0", [&](size_t i) { dDifference(model, qs[i], qs[nxt(i)], Jq, ARG0); },
      [&] { return cs(Jq); });
  run("d_difference_q1", [&](size_t i) { dDifference(model, qs[i], qs[nxt(i)], Jq, ARG1); },
      [&] { return cs(Jq); });
  if (g_sink == 12345.678)
    std::printf("#\n");
  return 0;
}
