#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "mc_flow/core/se3.h"

namespace mc_flow {
namespace {

Vector6d twist(double vx, double vy, double vz, double wx, double wy, double wz) {
  Vector6d xi;
  xi << vx, vy, vz, wx, wy, wz;
  return xi;
}

TEST(Se3, ExpOfZeroIsIdentity) { EXPECT_TRUE(se3Exp(Vector6d::Zero()).isApprox(Eigen::Matrix4d::Identity(), 1e-15)); }

TEST(Se3, ExpOfPureTranslationTranslates) {
  const Eigen::Matrix4d T = se3Exp(twist(0.3, -0.2, 1.5, 0, 0, 0));
  EXPECT_TRUE((T.topLeftCorner<3, 3>().isApprox(Eigen::Matrix3d::Identity(), 1e-15)));
  EXPECT_NEAR(T(0, 3), 0.3, 1e-15);
  EXPECT_NEAR(T(1, 3), -0.2, 1e-15);
  EXPECT_NEAR(T(2, 3), 1.5, 1e-15);
  EXPECT_TRUE(T.bottomRows<1>().isApprox(Eigen::RowVector4d(0, 0, 0, 1)));
}

TEST(Se3, RotationMatchesEigenAngleAxis) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, -2, 0.5).normalized();
  for (double angle : {1e-10, 1e-5, 0.1, 1.0, 2.5, 3.1}) {
    const Vector6d xi = twist(0, 0, 0, axis.x() * angle, axis.y() * angle, axis.z() * angle);
    const Eigen::Matrix3d expected = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
    EXPECT_TRUE((se3Exp(xi).topLeftCorner<3, 3>().isApprox(expected, 1e-12))) << "angle " << angle;
  }
}

TEST(Se3, ExpIsTheFlowOfTheTwist) {
  // exp(xi) equals the limit of many small steps (I + hat(xi)/N)^N, independent of the closed form.
  const Vector6d xi = twist(0.2, -0.1, 0.3, 0.4, -0.7, 0.2);
  Eigen::Matrix4d hat = Eigen::Matrix4d::Zero();
  hat.topLeftCorner<3, 3>() = skew(xi.tail<3>());
  hat.topRightCorner<3, 1>() = xi.head<3>();
  const int steps = 1 << 20;
  Eigen::Matrix4d step = Eigen::Matrix4d::Identity() + hat / steps + hat * hat / (2.0 * steps * steps);
  for (int i = 0; i < 20; ++i) step = step * step;  // step^(2^20)
  EXPECT_TRUE(se3Exp(xi).isApprox(step, 1e-9));
}

TEST(Se3, LogInvertsExpAcrossAngles) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (double angle : {0.0, 1e-12, 1e-9, 1e-7, 1e-4, 0.01, 0.5, 1.5, 2.8, 3.1}) {
    for (int trial = 0; trial < 5; ++trial) {
      Eigen::Vector3d axis(unit(rng), unit(rng), unit(rng));
      axis.normalize();
      Vector6d xi;
      xi.head<3>() = Eigen::Vector3d(unit(rng), unit(rng), unit(rng));
      xi.tail<3>() = axis * angle;
      const Vector6d back = se3Log(se3Exp(xi));
      EXPECT_LT((back - xi).norm(), 1e-9 * std::max(1.0, xi.norm())) << "angle " << angle;
    }
  }
}

TEST(Se3, ExpInvertsLogOfRigidTransform) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(2.0, Eigen::Vector3d(0.3, 0.4, -0.5).normalized()).toRotationMatrix();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(1.0, -2.0, 0.5);
  EXPECT_TRUE(se3Exp(se3Log(T)).isApprox(T, 1e-12));
}

TEST(Se3, SkewIsCrossProduct) {
  const Eigen::Vector3d a(0.3, -1.2, 2.0), b(-0.7, 0.1, 0.9);
  EXPECT_TRUE((skew(a) * b).isApprox(a.cross(b), 1e-15));
}

}  // namespace
}  // namespace mc_flow

TEST(Se3LeftJacobian, MatchesFiniteDifferencesOfTheExponential) {
  mc_flow::Vector6d xi;
  xi << 0.09, -0.04, 0.03, 0.05, -0.03, 0.04;
  const Eigen::Matrix4d T = mc_flow::se3Exp(xi);
  const mc_flow::Matrix6d J = mc_flow::se3LeftJacobian(xi);
  for (int k = 0; k < 6; ++k) {
    mc_flow::Vector6d d = mc_flow::Vector6d::Zero();
    d(k) = 1e-6;
    // exp(xi + d) exp(xi)^-1 = exp(J d) to first order
    const mc_flow::Vector6d eps = mc_flow::se3Log(mc_flow::se3Exp(xi + d) * T.inverse()) / 1e-6;
    for (int r = 0; r < 6; ++r) EXPECT_NEAR(eps(r), J(r, k), 1e-5) << "column " << k << " row " << r;
  }
  EXPECT_TRUE(mc_flow::se3LeftJacobian(mc_flow::Vector6d::Zero()).isIdentity(1e-12));
}
