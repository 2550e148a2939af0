// Pinocchio's RNEA, CRBA and ABA timed in C++ (batches of 200 calls cycling through 64 random
// states), for scripts/bench_pinocchio.py. The model comes serialised by Pinocchio's
// Python bindings: the wheel ships no urdfdom headers for its C++ URDF parser.
//
// States: q uniform within the joint limits (the free-flyer's translation, unbounded in the
// model, within ±1 m; without that bound randomConfiguration returns an infinite translation and
// every algorithm then runs on inf/NaN), v and a (ABA: τ) uniform in [-1, 1].
//
// CRBA is timed twice. "crba" is what upc's crba leaves behind: the world placements, the world
// joint Jacobian and M(q) with both triangles (Pinocchio's Convention::WORLD, which also fills
// data.oMi and data.J, followed by copying the upper triangle to the lower one). "crba_local" is
// Pinocchio's default (Convention::LOCAL): M's upper triangle only, no world quantities.
#include <pinocchio/multibody.hpp>
#include <pinocchio/serialization.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <chrono>
#include <cstdio>
#include <vector>
#include <algorithm>
using namespace pinocchio;
// Per-call time of the fastest of 50 batches of n calls: on a shared machine the batches that
// ran undisturbed (upc's side takes the fastest criterion sample the same way).
template <class F> double time_us(F f, int n) {
  double best = 1e300;
  for (int r = 0; r < 50; ++r) {
    auto s = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) f(i);
    auto e = std::chrono::steady_clock::now();
    best = std::min(best, std::chrono::duration<double, std::micro>(e - s).count() / n);
  }
  return best;
}
int main(int argc, char** argv) {
  Model model;
  model.loadFromBinary(argv[1]);
  if (model.njoints > 1 && model.joints[1].nq() == 7) {
    model.lowerPositionLimit.head<3>().setConstant(-1.0);
    model.upperPositionLimit.head<3>().setConstant(1.0);
  }
  Data data(model);
  const int K = 64, n = 200;
  std::vector<Eigen::VectorXd> q, v, a;
  for (int k = 0; k < K; ++k) {
    q.push_back(randomConfiguration(model));
    v.push_back(Eigen::VectorXd::Random(model.nv));
    a.push_back(Eigen::VectorXd::Random(model.nv));
  }
  // ABA is undefined where M(q) is singular (massless bodies): Pinocchio then returns NaN.
  bool aba_finite = true;
  for (int k = 0; k < K; ++k) aba_finite &= aba(model, data, q[k], v[k], a[k]).allFinite();
  double r = time_us([&](int i) { rnea(model, data, q[i % K], v[i % K], a[i % K]); }, n);
  double c = time_us(
      [&](int i) {
        crba(model, data, q[i % K], Convention::WORLD);
        data.M.triangularView<Eigen::StrictlyLower>() = data.M.transpose();
      },
      n);
  double cl = time_us([&](int i) { crba(model, data, q[i % K]); }, n);
  double b = time_us([&](int i) { aba(model, data, q[i % K], v[i % K], a[i % K]); }, n);
  std::printf(
      "{\"nv\": %d, \"rnea\": %.3f, \"crba\": %.3f, \"crba_local\": %.3f, \"aba\": %.3f, "
      "\"aba_finite\": %s}\n",
      model.nv, r, c, cl, b, aba_finite ? "true" : "false");
}
