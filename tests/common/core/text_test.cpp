#include "core/text.h"

#include <gtest/gtest.h>

#include <cmath>

namespace surgsim::core::text {
namespace {

TEST(Text, TrimStripsBlanksOnly) {
  EXPECT_EQ(trim("  a b\t\r\n"), "a b");
  EXPECT_EQ(trim(" \t "), "");
  EXPECT_EQ(trim(""), "");
}

TEST(Text, SplitKeepsEmptyFields) {
  const auto f = split("a,,b ,", ',');
  ASSERT_EQ(f.size(), 4u);
  EXPECT_EQ(f[0], "a");
  EXPECT_EQ(f[1], "");
  EXPECT_EQ(f[2], "b ");
  EXPECT_EQ(f[3], "");
  EXPECT_EQ(split("", ',').size(), 1u);
}

TEST(Text, SplitTrimmedCountsBeyondCapacity) {
  std::string_view out[2];
  EXPECT_EQ(split_trimmed(" x , y ,z", ',', out, 2), 3);
  EXPECT_EQ(out[0], "x");
  EXPECT_EQ(out[1], "y");
}

TEST(Text, ParseDoubleWholeFieldOnly) {
  double v = 0;
  EXPECT_EQ(parse_double(" 0.125 ", v), Number::kOk);
  EXPECT_EQ(v, 0.125);
  EXPECT_EQ(parse_double("+2e-3", v), Number::kOk);
  EXPECT_EQ(v, 2e-3);
  EXPECT_EQ(parse_double("-1", v), Number::kOk);
  EXPECT_EQ(v, -1.0);
  EXPECT_EQ(parse_double("1.5x", v), Number::kNotNumber);
  EXPECT_EQ(parse_double("", v), Number::kNotNumber);
  EXPECT_EQ(parse_double("++1", v), Number::kNotNumber);
  EXPECT_EQ(parse_double("1e999", v), Number::kOutOfRange);
  EXPECT_EQ(parse_double("nan", v), Number::kNotFinite);
  EXPECT_TRUE(std::isnan(v));
  EXPECT_EQ(parse_double("-inf", v), Number::kNotFinite);
}

TEST(Text, ParseDoubleIsCorrectlyRounded) {
  double v = 0;
  ASSERT_EQ(parse_double("0.1", v), Number::kOk);
  EXPECT_EQ(v, 0.1);
  ASSERT_EQ(parse_double("2.2250738585072014e-308", v), Number::kOk);
  EXPECT_EQ(v, 2.2250738585072014e-308);
}

TEST(Text, ParseIntAndHelpers) {
  long long i = 0;
  EXPECT_TRUE(parse_int(" 42", i));
  EXPECT_EQ(i, 42);
  EXPECT_FALSE(parse_int("4.2", i));
  EXPECT_FALSE(parse_int("99999999999999999999", i));
  EXPECT_EQ(lower("NrRd"), "nrrd");
  EXPECT_EQ(quote("abc"), "'abc'");
  EXPECT_EQ(quote(std::string(70, 'x'), 60), "'" + std::string(60, 'x') + "...'");
}

}  // namespace
}  // namespace surgsim::core::text
