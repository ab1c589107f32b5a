#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "pedalwave/model/model.hpp"

using namespace pedalwave::model;

namespace {
std::string rejection(const Params& p) {
  try {
    validate(p);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Params, PaperDefaultsAreValid) {
  const Params p = paper_params();
  EXPECT_NO_THROW(validate(p));
  EXPECT_EQ(p.N, 6);
  EXPECT_DOUBLE_EQ(2 * p.l, 0.07);
  EXPECT_NEAR(p.I_l, 4.08e-5, 1e-7);
  EXPECT_NEAR(p.n * p.n * p.I_r, 3.25e-3, 1e-5);
}

TEST(Params, ImpossibleValuesAreRejectedByName) {
  Params p = paper_params();
  p.N = 1;
  EXPECT_NE(rejection(p).find("N = 1"), std::string::npos) << rejection(p);
  p = paper_params();
  p.N = 65;
  EXPECT_NE(rejection(p).find("N = 65"), std::string::npos);
  p = paper_params();
  p.m_l = -0.1;
  EXPECT_NE(rejection(p).find("m_l = -0.1"), std::string::npos) << rejection(p);
  p = paper_params();
  p.I_r = 0.0;
  const std::string msg = rejection(p);
  EXPECT_NE(msg.find("I_r = 0"), std::string::npos) << msg;
  EXPECT_NE(msg.find("rigid"), std::string::npos) << "should suggest the rigid model: " << msg;
  p.joints = JointModel::kRigid;  // a massless motor is fine when β ≡ α
  EXPECT_EQ(rejection(p), "");
  p = paper_params();
  p.g = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(rejection(p).find("g = nan"), std::string::npos) << rejection(p);
  p = paper_params();
  p.K = {1.0, 2.0};
  EXPECT_NE(rejection(p).find("K has 2 entries"), std::string::npos) << rejection(p);
  p = paper_params();
  p.K = {1, 1, -1, 1, 1};
  EXPECT_NE(rejection(p).find("K[2] = -1"), std::string::npos) << rejection(p);
}

TEST(Params, ModelConstructorValidates) {
  Params p = paper_params();
  p.n = 0;
  EXPECT_THROW(Model{p}, std::invalid_argument);
}

TEST(Params, AnyNFrom2To64) {
  for (int N : {2, 3, 6, 17, 64}) {
    Model m(paper_params(N));
    EXPECT_EQ(m.nq(), 2 * N + 1);
    EXPECT_EQ(m.points(), 2 * N + 1);
    Params r = paper_params(N);
    r.joints = JointModel::kRigid;
    EXPECT_EQ(Model(r).nq(), N + 2);
  }
}
