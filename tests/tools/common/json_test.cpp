// The minimal JSON reader/writer (tools/common/src/json.cpp): every value kind, escapes and
// surrogate pairs, number grammar, errors that name the place, and a dump/parse round trip.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "pedalwave/toolkit/json.hpp"

namespace tk = pedalwave::toolkit;
using tk::Json;

TEST(Json, ReadsEveryKindOfValue) {
  const Json j = Json::parse(R"({"a": 1, "b": [true, false, null], "c": {"d": "x"}, "e": -2.5e-3,
                                 "f": [], "g": {}, "h": 0})");
  ASSERT_TRUE(j.is_object());
  EXPECT_EQ(j.size(), 7u);
  EXPECT_EQ(j["a"].number(), 1.0);
  EXPECT_TRUE(j["b"][0].boolean());
  EXPECT_FALSE(j["b"][1].boolean());
  EXPECT_TRUE(j["b"][2].is_null());
  EXPECT_EQ(j["c"]["d"].string(), "x");
  EXPECT_DOUBLE_EQ(j["e"].number(), -2.5e-3);
  EXPECT_TRUE(j["f"].is_array());
  EXPECT_EQ(j["f"].size(), 0u);
  EXPECT_TRUE(j["g"].is_object());
  EXPECT_EQ(j["h"].number(), 0.0);
  // member order is the input's
  EXPECT_EQ(j.members()[2].first, "c");
  // missing keys and out-of-range indices read as null, typed fallbacks apply
  EXPECT_TRUE(j["nope"].is_null());
  EXPECT_TRUE(j["b"][9].is_null());
  EXPECT_TRUE(j["a"]["x"].is_null());
  EXPECT_EQ(j["nope"].number_or(7.0), 7.0);
  EXPECT_EQ(j["c"]["d"].string_or("y"), "x");
  EXPECT_TRUE(j.contains("a"));
  EXPECT_FALSE(j.contains("z"));
}

TEST(Json, RepeatedKeysAreKeptAndTheLastIsFound) {
  // The runtime's report schema names "driver" twice (the driver's name and its counters).
  const Json j = Json::parse(R"({"driver": "serial", "rate_hz": 500, "driver": {"missing": 0}})");
  EXPECT_EQ(j.size(), 3u);
  EXPECT_EQ(j.members()[0].second.string(), "serial");
  EXPECT_TRUE(j["driver"].is_object());
  EXPECT_EQ(j["driver"]["missing"].number(), 0.0);
  EXPECT_EQ(Json::parse(j.dump()).dump(), j.dump()) << "written back as read";
}

TEST(Json, StringEscapesAndUnicode) {
  const Json j = Json::parse(R"(["q\"b\\s\/n\nr\rt\tb\bf\f", "\u00b5s", "\u20ac", "\ud83d\ude00", "µ raw"])");
  EXPECT_EQ(j[0].string(), "q\"b\\s/n\nr\rt\tb\bf\f");
  EXPECT_EQ(j[1].string(), "µs");
  EXPECT_EQ(j[2].string(), "€");
  EXPECT_EQ(j[3].string(), "\xF0\x9F\x98\x80");  // U+1F600 from a surrogate pair
  EXPECT_EQ(j[4].string(), "µ raw");
  EXPECT_EQ(tk::json_quote("a\"b\\c\n\x01"), "\"a\\\"b\\\\c\\n\\u0001\"");
}

TEST(Json, NumberGrammar) {
  EXPECT_EQ(Json::parse("123456789012").number(), 123456789012.0);
  EXPECT_EQ(Json::parse("-0").number(), 0.0);
  EXPECT_DOUBLE_EQ(Json::parse("1E+2").number(), 100.0);
  EXPECT_DOUBLE_EQ(Json::parse("0.5").number(), 0.5);
  EXPECT_TRUE(std::isinf(Json::parse("1e999").number()));
  EXPECT_EQ(Json::parse("1e-999").number(), 0.0);
  for (const char* bad : {"01", "1.", ".5", "+1", "-", "1e", "1e+", "0x10", "NaN", "Infinity"})
    EXPECT_THROW((void)Json::parse(bad), tk::JsonError) << bad;
}

TEST(Json, ErrorsNameSourceLineAndColumn) {
  try {
    (void)Json::parse("{\n  \"a\": 1,\n  \"b\" 2\n}", "report.json");
    FAIL() << "no error";
  } catch (const tk::JsonError& e) {
    EXPECT_STREQ(e.what(), "report.json:3:7: expected ':' after the member name, found '2'");
  }
  for (const char* bad : {"", "{", "[1,]", "{\"a\":1,}", "[1 2]", "\"abc", "\"\\x\"", "\"\\ud800\"",
                          "\"\\udc00\"", "\"a\nb\"", "tru", "{} x", "{1:2}"})
    EXPECT_THROW((void)Json::parse(bad), tk::JsonError) << bad;
  EXPECT_THROW((void)Json::parse(std::string(600, '[') + std::string(600, ']')), tk::JsonError);
  EXPECT_THROW((void)Json::parse("1").string(), tk::JsonError);
  try {
    (void)Json::parse_file("/nonexistent/report.json");
    FAIL() << "no error";
  } catch (const tk::JsonError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/report.json"), std::string::npos);
  }
}

TEST(Json, BuildDumpAndReadBack) {
  Json o = Json::object();
  o.set("name", "soak \"1\"");
  o.set("n", 2);
  o.set("x", 0.1);
  o.set("nan", std::nan(""));
  o.set("ok", true);
  Json bins = Json::array();
  bins.push(Json(Json::Array{0, 10, 5}));
  bins.push(Json(Json::Array{10, 20, 1}));
  o.set("bins", bins);
  Json samples;
  samples.push(Json::object().set("t", 0.0).set("rss_kB", 1234));
  o.set("samples", samples);
  o.set("n", 3);  // replaces
  EXPECT_EQ(o.dump(), R"({"name":"soak \"1\"","n":3,"x":0.1,"nan":null,"ok":true,"bins":[[0,10,5],[10,20,1]],"samples":[{"t":0,"rss_kB":1234}]})");
  for (int indent : {-1, 0, 2}) {
    const Json back = Json::parse(o.dump(indent));
    EXPECT_EQ(back.dump(), o.dump()) << indent;
  }
  const std::string pretty = o.dump(2);
  EXPECT_NE(pretty.find("\n  \"bins\": [[0, 10, 5], [10, 20, 1]]"), std::string::npos) << pretty;

  const auto path = std::filesystem::temp_directory_path() / "pedalwave_json_test.json";
  std::ofstream(path) << pretty;
  EXPECT_EQ(Json::parse_file(path)["samples"][0]["rss_kB"].number(), 1234.0);
  std::filesystem::remove(path);
  EXPECT_THROW(Json(1).set("a", 1), tk::JsonError);
  EXPECT_THROW(Json::object().push(1), tk::JsonError);
}
