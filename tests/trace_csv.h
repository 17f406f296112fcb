#pragma once
// Reading a trace.csv written by master_station (one row per haptic tick; the "phase" column is
// text, every other column a number), for the end-to-end tests.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct Trace {
  std::vector<std::string> columns;
  std::vector<std::string> phase;
  std::map<std::string, std::vector<double>> values;
  std::vector<double> Select(const std::string& column, const std::string& which) const {
    std::vector<double> out;
    const auto& v = values.at(column);
    for (size_t i = 0; i < v.size(); ++i)
      if (phase[i] == which) out.push_back(v[i]);
    return out;
  }
};

Trace LoadTrace(const std::string& dir) {
  Trace t;
  std::ifstream in(dir + "/trace.csv");
  EXPECT_TRUE(in.good()) << "no trace at " << dir << "/trace.csv";
  std::string line;
  std::getline(in, line);
  std::stringstream header(line);
  for (std::string c; std::getline(header, c, ',');) t.columns.push_back(c);
  while (std::getline(in, line)) {
    std::stringstream row(line);
    std::string cell;
    for (size_t i = 0; std::getline(row, cell, ','); ++i) {
      if (t.columns[i] == "phase") {
        t.phase.push_back(cell);
      } else {
        t.values[t.columns[i]].push_back(std::strtod(cell.c_str(), nullptr));
      }
    }
  }
  return t;
}

}  // namespace
