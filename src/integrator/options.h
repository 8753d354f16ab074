#pragma once
// Reading integrator options with unused-key reporting (private to src/integrator).

#include "voxcone/core/error.h"

#include <nlohmann/json.hpp>

#include <set>
#include <string>
#include <vector>

namespace voxcone {

/// Reads the options of one integrator and reports any key it did not read.
class OptionReader {
public:
  OptionReader(const nlohmann::json& options, std::string integrator)
      : m_options(options), m_integrator(std::move(integrator)) {
    if (!m_options.is_object()) throw SettingsError(m_integrator + ": options must be a JSON object");
  }
  int integer(const std::string& key, int def, int lo, int hi) {
    if (!m_options.contains(key)) return def;
    m_used.insert(key);
    const auto& v = m_options.at(key);
    if (!v.is_number_integer()) throw SettingsError(m_integrator + "." + key + ": expected an integer");
    const auto i = v.get<int64_t>();
    if (i < lo || i > hi)
      throw SettingsError(m_integrator + "." + key + ": value " + std::to_string(i) + " out of range [" +
                          std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return static_cast<int>(i);
  }
  double number(const std::string& key, double def, double lo, double hi) {
    if (!m_options.contains(key)) return def;
    m_used.insert(key);
    const auto& v = m_options.at(key);
    if (!v.is_number()) throw SettingsError(m_integrator + "." + key + ": expected a number");
    const double d = v.get<double>();
    if (!std::isfinite(d) || d < lo || d > hi)
      throw SettingsError(m_integrator + "." + key + ": value " + std::to_string(d) + " out of range [" +
                          std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return d;
  }
  /// A string (`def` when absent).
  std::string text(const std::string& key, const std::string& def) {
    if (!m_options.contains(key)) return def;
    m_used.insert(key);
    const auto& v = m_options.at(key);
    if (!v.is_string()) throw SettingsError(m_integrator + "." + key + ": expected a string");
    return v.get<std::string>();
  }
  bool has(const std::string& key) const { return m_options.contains(key); }
  /// One of `choices` (the first is the default).
  std::string choice(const std::string& key, const std::vector<std::string>& choices) {
    if (!m_options.contains(key)) return choices.front();
    m_used.insert(key);
    const auto& v = m_options.at(key);
    std::string list;
    for (const std::string& c : choices) list += (list.empty() ? "" : ", ") + c;
    if (v.is_string())
      for (const std::string& c : choices)
        if (v.get<std::string>() == c) return c;
    throw SettingsError(m_integrator + "." + key + ": expected one of " + list);
  }
  void finish() const {
    for (auto it = m_options.begin(); it != m_options.end(); ++it)
      if (!m_used.count(it.key())) throw SettingsError(m_integrator + "." + it.key() + ": unknown option");
  }

private:
  const nlohmann::json& m_options;
  std::string m_integrator;
  std::set<std::string> m_used;
};

}  // namespace voxcone
