// The one status list: C++14 tables, each status named and explained, and nothing past it.
#include <gtest/gtest.h>

#include <cstring>
#include <set>
#include <string>

#include "graspguide_cue/status.h"

namespace gg = graspguide;

TEST(Status, EveryStatusHasItsOwnNameAndAMessage) {
  std::set<std::string> names;
  for (int i = 0; i < gg::kStatusCount; ++i) {
    const gg::Status s = static_cast<gg::Status>(i);
    EXPECT_STRNE(gg::status_name(s), "unknown");
    EXPECT_GT(std::strlen(gg::status_message(s)), 1u);
    names.insert(gg::status_name(s));
  }
  EXPECT_EQ(names.size(), size_t(gg::kStatusCount));
  EXPECT_STREQ(gg::status_name(static_cast<gg::Status>(gg::kStatusCount)), "unknown");
  EXPECT_STREQ(gg::status_message(static_cast<gg::Status>(255)), "unknown status");
  static_assert(gg::status_name(gg::Status::kOk)[0] == 'o', "usable in constant expressions");
}
