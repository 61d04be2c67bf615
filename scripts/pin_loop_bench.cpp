// Pinocchio 4.1.0 (PyPI wheel `pin`) timings of the constrained dynamics with closed kinematic
// loops (two-joint RigidConstraintModels) mixed with world contacts, for
// scripts/compare-loops.sh: the counterpart of `sodyn bench --algos kkt_fo,impact_fo` with
// `--contacts A:B,...` or `--model-constraints`. The timing and state code is
// scripts/pin_timing.hpp, shared with pin_kin_bench.cpp (pre-generated states round robin,
// warm-up, median/p10/p90 per call); the line format is pin_bench's (`algo=NAME median_us=...`).
//
// Usage:
//   pin_loop_bench URDF ff|fixed ITERS --contacts F1,A:B,... [--contact-type 3D|6D]
//       [--contact-ref LOCAL|LOCAL_WORLD_ALIGNED] [options]
//   pin_loop_bench --binary MODEL.bin --loops FILE ITERS [options]
// options: [--name N] [--nstates 1000] [--max-seconds 1] [--algos a,b]
//
// An entry A:B of --contacts is a constraint of --contact-type between frame A's and frame B's
// placements (joint1 = A's parent joint, joint2 = B's); F alone holds frame F in the world. With
// --binary, the model is a pinocchio::Model saved by Model.saveToBinary
// (scripts/make_pin_loop_models.py: the twins of builtin:fourbar and builtin:delta) and FILE
// lists one 3-D LOCAL_WORLD_ALIGNED loop per line: "joint1 x y z joint2 x y z" (the two points
// in their joints' frames), as sodyn's built-ins' constraints.
//
// Algorithms (each timed as pin_bench times the world-contact ones, so that the ratios are
// those of scripts/compare-pinocchio.sh):
//   constraintDynamics                    the KKT forward dynamics
//   computeConstraintDynamicsDerivatives  its first-order derivatives, timed alone
//                                         (constraintDynamics untimed before each call)
//   constraintDynamics+derivatives        the two together, timed as one call
//   impulseDynamics, computeImpulseDynamicsDerivatives, impulseDynamics+derivatives
//                                         the same for the impact (r_coeff = 0)
// Settings: ProximalSettings defaults (mu = 0, one iteration), as pin_bench.

#include <pinocchio/parsers/urdf.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/constrained-dynamics-derivatives.hpp>
#include <pinocchio/algorithm/impulse-dynamics.hpp>
#include <pinocchio/algorithm/impulse-dynamics-derivatives.hpp>
#include <pinocchio/serialization/model.hpp>

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

int main(int argc, char ** argv)
{
  if (argc < 4)
  {
    std::cerr << "usage: " << argv[0] << " URDF ff|fixed ITERS --contacts F1,A:B,... [options]\n"
              << "       " << argv[0] << " --binary MODEL.bin --loops FILE ITERS [options]\n";
    return 1;
  }
  Model model;
  bool ff = false, binary = false;
  std::string source = argv[1];
  if (source == "--binary")
  {
    binary = true;
    source = argv[2];
    model.loadFromBinary(source);
    ff = model.njoints > 1 && model.joints[1].shortname() == "JointModelFreeFlyer";
  }
  else
  {
    const std::string base = argv[2];
    if (base != "ff" && base != "fixed")
    {
      std::cerr << "second argument must be ff or fixed\n";
      return 1;
    }
    ff = base == "ff";
    if (ff)
      pinocchio::urdf::buildModel(source, JointModelFreeFlyer(), model);
    else
      pinocchio::urdf::buildModel(source, model);
  }
  int argi = 3;
  std::string loops_file;
  if (binary)
  {
    if (std::string(argv[3]) != "--loops" || argc < 6)
    {
      std::cerr << "--binary MODEL.bin --loops FILE ITERS\n";
      return 1;
    }
    loops_file = argv[4];
    argi = 5;
  }
  const size_t iters = (size_t)std::atol(argv[argi++]);
  std::string name = model.name;
  size_t nstates = 1000;
  std::vector<std::string> contacts;
  std::string contact_type = "3D", contact_ref = "LOCAL";
  std::set<std::string> only;
  double max_seconds = 1.0;
  for (int i = argi; i < argc; ++i)
  {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc)
      {
        std::cerr << a << " needs a value\n";
        std::exit(1);
      }
      return argv[++i];
    };
    if (a == "--name")
      name = next();
    else if (a == "--nstates")
      nstates = (size_t)std::atol(next().c_str());
    else if (a == "--contacts")
      contacts = split(next(), ',');
    else if (a == "--contact-type")
      contact_type = next();
    else if (a == "--contact-ref")
      contact_ref = next();
    else if (a == "--max-seconds")
      max_seconds = std::atof(next().c_str());
    else if (a == "--algos")
      for (auto & s : split(next(), ','))
        only.insert(s);
    else
    {
      std::cerr << "unknown option " << a << "\n";
      return 1;
    }
  }
  auto want = [&](const std::string & algo) { return only.empty() || only.count(algo) > 0; };

  typedef std::vector<RigidConstraintModel> CMVec;
  typedef std::vector<RigidConstraintData> CDVec;
  CMVec cmodels;
  const ContactType ct = (contact_type == "6D") ? CONTACT_6D : CONTACT_3D;
  const ReferenceFrame rf = (contact_ref == "LOCAL_WORLD_ALIGNED") ? LOCAL_WORLD_ALIGNED : LOCAL;
  auto frame = [&](const std::string & f) -> const Frame & {
    if (!model.existFrame(f))
    {
      std::cerr << "frame not found: " << f << "\n";
      std::exit(1);
    }
    return model.frames[model.getFrameId(f)];
  };
  for (const auto & c : contacts)
  {
    const size_t colon = c.find(':');
    if (colon == std::string::npos)
    {
      const Frame & fr = frame(c);
      cmodels.push_back(RigidConstraintModel(ct, model, fr.parentJoint, fr.placement, rf));
    }
    else
    {
      const Frame & a = frame(c.substr(0, colon));
      const Frame & b = frame(c.substr(colon + 1));
      cmodels.push_back(RigidConstraintModel(
        ct, model, a.parentJoint, a.placement, b.parentJoint, b.placement, rf));
    }
    cmodels.back().name = c;
  }
  if (binary)
  {
    std::ifstream fin(loops_file);
    if (!fin)
    {
      std::cerr << "cannot open " << loops_file << "\n";
      return 1;
    }
    long j1, j2;
    double x1, y1, z1, x2, y2, z2;
    while (fin >> j1 >> x1 >> y1 >> z1 >> j2 >> x2 >> y2 >> z2)
    {
      const SE3 p1(SE3::Matrix3::Identity(), SE3::Vector3(x1, y1, z1));
      const SE3 p2(SE3::Matrix3::Identity(), SE3::Vector3(x2, y2, z2));
      cmodels.push_back(RigidConstraintModel(
        CONTACT_3D, model, (JointIndex)j1, p1, (JointIndex)j2, p2, LOCAL_WORLD_ALIGNED));
      contacts.push_back("loop" + std::to_string(contacts.size()));
    }
    contact_type = "3D";
    contact_ref = "LOCAL_WORLD_ALIGNED";
  }
  if (cmodels.empty())
  {
    std::cerr << "no constraints\n";
    return 1;
  }
  CDVec cdatas;
  for (const auto & cm : cmodels)
    cdatas.push_back(RigidConstraintData(cm));

  Eigen::VectorXd lower, upper;
  sampling_bounds(model, ff, lower, upper);
  std::srand(42);
  std::vector<Eigen::VectorXd> qs(nstates), vs(nstates), taus(nstates);
  for (size_t i = 0; i < nstates; ++i)
  {
    qs[i] = randomConfiguration(model, lower, upper);
    vs[i] = Eigen::VectorXd::Random(model.nv);
    taus[i] = Eigen::VectorXd::Random(model.nv);
  }
  Data data(model);
  ProximalSettingsTpl<double> settings; // defaults: mu = 0, max_iter = 1, accuracy 1e-12
  initConstraintDynamics(model, data, cmodels, cdatas);
  std::string list;
  for (auto & c : contacts)
    list += (list.empty() ? "" : ",") + c;
  std::printf(
    "# model=%s source=%s base=%s nq=%d nv=%d nstates=%zu contacts=%s contact_type=%s "
    "contact_ref=%s constraint_dim=%d\n",
    name.c_str(), source.c_str(), ff ? "ff" : "fixed", model.nq, model.nv, nstates, list.c_str(),
    contact_type.c_str(), contact_ref.c_str(), (int)data.constraint_chol.constraintDim());
  auto report = [&](const char * algo, const Stats & s) {
    std::printf(
      "model=%s nq=%d nv=%d algo=%s median_us=%.4f p10_us=%.4f p90_us=%.4f batch=%zu "
      "samples=%zu\n",
      name.c_str(), model.nq, model.nv, algo, s.med, s.p10, s.p90, s.batch, s.nsamples);
    std::fflush(stdout);
  };
  auto fwd = [&](size_t i) {
    constraintDynamics(model, data, qs[i], vs[i], taus[i], cmodels, cdatas, settings);
  };
  auto dfwd = [&](size_t) {
    computeConstraintDynamicsDerivatives(model, data, cmodels, cdatas, settings);
  };
  const double r_coeff = 0.0;
  auto imp = [&](size_t i) {
    impulseDynamics(model, data, qs[i], vs[i], cmodels, cdatas, r_coeff, settings);
  };
  auto dimp = [&](size_t) {
    computeImpulseDynamicsDerivatives(model, data, cmodels, cdatas, r_coeff, settings);
  };
  if (want("constraintDynamics"))
    report("constraintDynamics", bench(fwd, nstates, iters, max_seconds));
  if (want("computeConstraintDynamicsDerivatives"))
    report(
      "computeConstraintDynamicsDerivatives", bench_pre(fwd, dfwd, nstates, iters, max_seconds));
  if (want("constraintDynamics+derivatives"))
    report(
      "constraintDynamics+derivatives", bench(
                                          [&](size_t i) {
                                            fwd(i);
                                            dfwd(i);
                                          },
                                          nstates, iters, max_seconds));
  if (want("impulseDynamics"))
    report("impulseDynamics", bench(imp, nstates, iters, max_seconds));
  if (want("computeImpulseDynamicsDerivatives"))
    report(
      "computeImpulseDynamicsDerivatives", bench_pre(imp, dimp, nstates, iters, max_seconds));
  if (want("impulseDynamics+derivatives"))
    report(
      "impulseDynamics+derivatives", bench(
                                       [&](size_t i) {
                                         imp(i);
                                         dimp(i);
                                       },
                                       nstates, iters, max_seconds));
  g_sink = g_sink + data.ddq[0];
  if (g_sink == 12345.678)
    std::printf("#\n");
  return 0;
}
