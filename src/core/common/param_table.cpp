#include "fisheye_mapping/core/common/param_table.h"

#include <cmath>
#include <sstream>

namespace fisheye_mapping {

const char* toString(ParamKind kind) {
  switch (kind) {
    case ParamKind::Bool: return "bool";
    case ParamKind::Int: return "int";
    case ParamKind::Double: return "double";
    case ParamKind::String: return "string";
    case ParamKind::Enum: return "enum";
    case ParamKind::DoubleList: return "double list";
    case ParamKind::StringList: return "string list";
    case ParamKind::StringMap: return "string map";
  }
  return "?";
}

namespace {
std::string number(double v) {
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}
}  // namespace

bool ParamRange::contains(double v) const {
  if (!std::isfinite(v)) return false;
  if (min_open ? !(v > min) : !(v >= min)) return false;
  if (max_open ? !(v < max) : !(v <= max)) return false;
  return true;
}

std::string ParamRange::text() const {
  const bool lo = std::isfinite(min), hi = std::isfinite(max);
  if (!lo && !hi) return "finite";
  if (lo && !hi) return (min_open ? "> " : ">= ") + number(min);
  if (!lo && hi) return (max_open ? "< " : "<= ") + number(max);
  return std::string(min_open ? "(" : "[") + number(min) + ", " + number(max) + (max_open ? ")" : "]");
}

std::string formatParamValue(const ParamValue& v) {
  struct Visitor {
    std::string operator()(bool b) const { return b ? "true" : "false"; }
    std::string operator()(int i) const { return std::to_string(i); }
    std::string operator()(double d) const { return std::isnan(d) ? "unset" : number(d); }
    std::string operator()(const std::string& s) const { return "\"" + s + "\""; }
    std::string operator()(const std::vector<double>& l) const {
      std::string s = "[";
      for (size_t i = 0; i < l.size(); ++i) s += (i ? ", " : "") + number(l[i]);
      return s + "]";
    }
    std::string operator()(const std::vector<std::string>& l) const {
      std::string s = "[";
      for (size_t i = 0; i < l.size(); ++i) s += (i ? ", \"" : "\"") + l[i] + "\"";
      return s + "]";
    }
    std::string operator()(const std::map<std::string, std::string>& m) const {
      std::string s = "{";
      for (const auto& [k, v] : m) s += (s.size() > 1 ? ", " : "") + k + ": \"" + v + "\"";
      return s + "}";
    }
  };
  return std::visit(Visitor{}, v);
}

std::string ParamInfo::allowed() const {
  switch (kind) {
    case ParamKind::Bool: return "true | false";
    case ParamKind::Int:
    case ParamKind::Double: return range.text();
    case ParamKind::Enum: {
      std::string s;
      for (const auto& c : choices) s += (s.empty() ? "" : " | ") + c;
      return s;
    }
    case ParamKind::DoubleList: {
      std::string s = list_size ? std::to_string(list_size) + " numbers" : "numbers";
      if (range.bounded()) s += ", each " + range.text();
      return s;
    }
    case ParamKind::String: return "a string";
    case ParamKind::StringList: return "a list of strings";
    case ParamKind::StringMap: return "a map of strings";
  }
  return "?";
}

void requireInRange(const std::string& name, const ParamRange& range, double v, const std::string& unit) {
  if (range.contains(v)) return;
  std::ostringstream s;
  s << name << ": must be " << range.text() << (unit.empty() ? "" : " " + unit) << ", got " << number(v);
  throw std::invalid_argument(s.str());
}

std::vector<std::string> yamlKeys(const YAML::Node& node) {
  std::vector<std::string> keys;
  if (!node.IsMap()) return keys;
  for (const auto& kv : node) keys.push_back(kv.first.as<std::string>());
  return keys;
}

}  // namespace fisheye_mapping
