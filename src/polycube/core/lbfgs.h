// Preconditioned L-BFGS with Armijo backtracking, for the untangling energies (chart/realize*.cpp).
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <functional>
#include <vector>

namespace polycube {

struct LbfgsOptions {
  int memory = 8;                ///< correction pairs kept
  int max_iterations = 300;      ///< accepted steps at most
  double decrease_tol = 1e-13;   ///< stop when a step lowers the energy by less than this, relatively
  /// Largest change of one unknown tried first (0 = no limit): the line search starts at the step
  /// that moves no unknown further than this. Untangling nearly flat tets gives preconditioned
  /// directions 1e5 x too long, beyond what 30 halvings bring back.
  double max_change = 0;
};

/// Minimizes f from z (updated in place) by L-BFGS (two-loop recursion with H0 = gamma P^-1, P^-1
/// applied by `precondition`), each step backtracked until the Armijo condition holds. f(z, g)
/// returns the energy and fills g when it is non-null. `stop(iteration)`, if given, is asked after
/// every accepted step whether to end. A direction that does not descend restarts from the
/// preconditioned gradient. Returns the accepted steps; E receives the final energy.
inline int lbfgs_minimize(Eigen::VectorXd& z, const std::function<double(const Eigen::VectorXd&, Eigen::VectorXd*)>& f,
                          const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& precondition,
                          const LbfgsOptions& opt, double& E, const std::function<bool(int)>& stop = {}) {
  // P^-1 is linear, so with P^-1 g kept per iterate and P^-1 y_i = P^-1 g_(i+1) - P^-1 g_i per
  // pair, the two-loop recursion needs one application of P^-1 per step (P^-1 q = P^-1 g -
  // sum a_i P^-1 y_i), not two.
  std::vector<Eigen::VectorXd> S, Yv, KYv;
  std::vector<double> rho;
  Eigen::VectorXd g, gt;
  E = f(z, &g);
  Eigen::VectorXd Kg = precondition(g);
  int it = 0;
  while (it < opt.max_iterations) {
    Eigen::VectorXd q = g, Kq = Kg;
    std::vector<double> a(S.size());
    for (int i = static_cast<int>(S.size()) - 1; i >= 0; --i) {
      a[i] = rho[i] * S[i].dot(q);
      q -= a[i] * Yv[i];
      Kq -= a[i] * KYv[i];
    }
    Eigen::VectorXd r = std::move(Kq);
    if (!S.empty()) r *= S.back().dot(Yv.back()) / std::max(Yv.back().dot(KYv.back()), 1e-300);
    for (size_t i = 0; i < S.size(); ++i) r += (a[i] - rho[i] * Yv[i].dot(r)) * S[i];
    Eigen::VectorXd d = -r;
    double slope = d.dot(g);
    if (!(slope < 0)) {
      S.clear(), Yv.clear(), KYv.clear(), rho.clear();
      d = -Kg;
      slope = d.dot(g);
      if (!(slope < 0)) break;
    }
    double step = 1, Et = E;
    if (opt.max_change > 0) step = std::min(1.0, opt.max_change / std::max(d.lpNorm<Eigen::Infinity>(), 1e-300));
    bool ok = false;
    for (int ls = 0; ls < 30; ++ls, step *= 0.5) {
      Et = f(z + step * d, &gt);
      if (Et <= E + 1e-4 * step * slope) {
        ok = true;
        break;
      }
    }
    if (!ok) break;
    const Eigen::VectorXd sv = step * d, yv = gt - g;
    Eigen::VectorXd Kgt = precondition(gt);
    z += sv;
    const double decrease = E - Et;
    E = Et;
    ++it;
    const double sy = sv.dot(yv);
    if (sy > 1e-300) {
      if (static_cast<int>(S.size()) == opt.memory)
        S.erase(S.begin()), Yv.erase(Yv.begin()), KYv.erase(KYv.begin()), rho.erase(rho.begin());
      S.push_back(sv);
      Yv.push_back(yv);
      KYv.push_back(Kgt - Kg);
      rho.push_back(1 / sy);
    }
    g = gt;
    Kg = std::move(Kgt);
    if (decrease < opt.decrease_tol * std::abs(E)) break;
    if (stop && stop(it - 1)) break;
  }
  return it;
}

}  // namespace polycube
