#include "dds_support.h"

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/rtps/attributes/ServerAttributes.h>
#include <fastdds/rtps/transport/SocketTransportDescriptor.h>
#include <fastrtps/types/TypesBase.h>
#include <fastrtps/utils/IPLocator.h>
#include <netdb.h>
#include <sys/socket.h>
#include <arpa/inet.h>

#include <cstdlib>
#include <sstream>
#include <stdexcept>

namespace surgsim::dds {

using namespace eprosima::fastdds::dds;
using eprosima::fastrtps::types::ReturnCode_t;

int default_domain() {
  if (const char* env = std::getenv("SURGSIM_DOMAIN")) {
    char* end = nullptr;
    const long v = std::strtol(env, &end, 10);
    if (end != env && *end == '\0' && v >= 0 && v <= 232) return static_cast<int>(v);
    throw std::runtime_error(std::string("SURGSIM_DOMAIN='") + env + "' is not a DDS domain id (0..232)");
  }
  return 0;
}

std::string participant_profile(const std::string& requested) {
  if (!requested.empty()) return requested;
  const char* env = std::getenv(kParticipantEnv);
  return env != nullptr && *env != '\0' ? std::string(env) : std::string("surgsim_default");
}

std::vector<std::pair<std::string, int>> parse_address_list(const std::string& text, const std::string& what) {
  std::vector<std::pair<std::string, int>> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    std::string host = item;
    int port = 0;
    const auto colon = item.rfind(':');
    if (colon != std::string::npos) {
      host = item.substr(0, colon);
      char* end = nullptr;
      const long p = std::strtol(item.c_str() + colon + 1, &end, 10);
      if (end == item.c_str() + colon + 1 || *end != '\0' || p < 1 || p > 65535) {
        throw std::runtime_error(what + ": '" + item + "' has no valid port (ADDR[:PORT], port 1..65535)");
      }
      port = static_cast<int>(p);
    }
    if (host.empty()) throw std::runtime_error(what + ": '" + item + "' has no address");
    out.emplace_back(host, port);
  }
  if (out.empty()) throw std::runtime_error(what + ": no address in '" + text + "'");
  return out;
}

namespace {

using eprosima::fastrtps::rtps::IPLocator;
using eprosima::fastrtps::rtps::Locator_t;

// An IPv4 UDP locator; host names are resolved here, at start-up.
Locator_t udp_locator(const std::string& host, int port, const std::string& what) {
  std::string address = host;
  if (!IPLocator::isIPv4(host)) {
    addrinfo hints{};
    hints.ai_family = AF_INET;
    addrinfo* res = nullptr;
    if (getaddrinfo(host.c_str(), nullptr, &hints, &res) != 0 || res == nullptr) {
      throw std::runtime_error(what + ": cannot resolve '" + host + "' to an IPv4 address");
    }
    char buf[INET_ADDRSTRLEN] = {0};
    inet_ntop(AF_INET, &reinterpret_cast<sockaddr_in*>(res->ai_addr)->sin_addr, buf, sizeof buf);
    freeaddrinfo(res);
    address = buf;
  }
  Locator_t loc;
  loc.kind = LOCATOR_KIND_UDPv4;
  IPLocator::setIPv4(loc, address);
  loc.port = static_cast<std::uint32_t>(port);
  return loc;
}

// Per-machine addresses from the environment, applied over the XML profile (config/dds/profiles.xml).
void apply_address_overrides(DomainParticipantQos& qos) {
  auto& builtin = qos.wire_protocol().builtin;
  if (const char* env = std::getenv(kPeersEnv); env != nullptr && *env != '\0') {
    builtin.initialPeersList.clear();
    for (const auto& [host, port] : parse_address_list(env, kPeersEnv)) {
      builtin.initialPeersList.push_back(udp_locator(host, port, kPeersEnv));
    }
  }
  if (const char* env = std::getenv(kDiscoveryServerEnv); env != nullptr && *env != '\0') {
    using eprosima::fastrtps::rtps::DiscoveryProtocol_t;
    const auto protocol = builtin.discovery_config.discoveryProtocol;
    if (protocol != DiscoveryProtocol_t::CLIENT && protocol != DiscoveryProtocol_t::SUPER_CLIENT) {
      return;  // only client profiles talk to a server; the others ignore the variable
    }
    auto& servers = builtin.discovery_config.m_DiscoveryServers;
    servers.clear();
    int id = 0;
    for (const auto& [host, port] : parse_address_list(env, kDiscoveryServerEnv)) {
      eprosima::fastrtps::rtps::RemoteServerAttributes server;
      eprosima::fastdds::rtps::get_server_client_default_guidPrefix(id++, server.guidPrefix);
      server.metatrafficUnicastLocatorList.push_back(udp_locator(host, port == 0 ? 11811 : port, kDiscoveryServerEnv));
      servers.push_back(server);
    }
  }
}

// "UDPv4 only, initial peers 192.168.77.1, 192.168.77.2" and the like, for the start-up log.
std::string describe(const DomainParticipantQos& qos) {
  std::ostringstream o;
  const auto& t = qos.transport();
  if (t.use_builtin_transports && t.user_transports.empty()) {
    o << "built-in transports (shared memory + UDPv4)";
  } else {
    o << (t.use_builtin_transports ? "built-in + " : "");
    bool first = true;
    for (const auto& d : t.user_transports) {
      const char* kind = dynamic_cast<const eprosima::fastdds::rtps::SocketTransportDescriptor*>(d.get()) != nullptr
                             ? "UDPv4" : "shared memory";
      o << (first ? "" : " + ") << kind;
      first = false;
    }
    o << " only";
  }
  const auto& b = qos.wire_protocol().builtin;
  using eprosima::fastrtps::rtps::DiscoveryProtocol_t;
  const auto protocol = b.discovery_config.discoveryProtocol;
  if (protocol == DiscoveryProtocol_t::CLIENT || protocol == DiscoveryProtocol_t::SUPER_CLIENT) {
    o << ", discovery server";
    for (const auto& s : b.discovery_config.m_DiscoveryServers) {
      for (const auto& l : s.metatrafficUnicastLocatorList) o << " " << IPLocator::ip_to_string(l) << ":" << l.port;
    }
  } else {
    o << ", multicast discovery";
    if (!b.metatrafficUnicastLocatorList.empty() && b.metatrafficMulticastLocatorList.empty()) o << " off";
    if (!b.initialPeersList.empty()) {
      o << ", initial peers";
      for (const auto& l : b.initialPeersList) {
        o << " " << IPLocator::ip_to_string(l);
        if (l.port != 0) o << ":" << l.port;
      }
    }
  }
  return o.str();
}

}  // namespace

Participant::Participant(const DdsOptions& options) {
  auto* factory = DomainParticipantFactory::get_instance();
  // $FASTRTPS_DEFAULT_PROFILES_FILE (or ./DEFAULT_FASTRTPS_PROFILES.xml) first: a site file may add profiles.
  factory->load_profiles();
  if (!options.profiles_file.empty() &&
      factory->load_XML_profiles_file(options.profiles_file) != ReturnCode_t::RETCODE_OK) {
    throw std::runtime_error(options.profiles_file + ": Fast DDS could not load this XML profiles file");
  }
  profile_ = participant_profile(options.participant_profile);
  DomainParticipantQos qos = PARTICIPANT_QOS_DEFAULT;
  if (factory->get_participant_qos_from_profile(profile_, qos) != ReturnCode_t::RETCODE_OK) {
    throw std::runtime_error("DDS participant profile '" + profile_ + "' not found in " +
                             (options.profiles_file.empty() ? std::string("the loaded profiles") : options.profiles_file));
  }
  apply_address_overrides(qos);
  description_ = describe(qos);
  qos.name(options.name);
  participant_ = factory->create_participant(options.domain, qos);
  if (participant_ == nullptr) {
    throw std::runtime_error("cannot create a DDS participant on domain " + std::to_string(options.domain));
  }
  publisher_ = participant_->create_publisher(PUBLISHER_QOS_DEFAULT);
  subscriber_ = participant_->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  if (publisher_ == nullptr || subscriber_ == nullptr) throw std::runtime_error("cannot create DDS publisher/subscriber");
}

Participant::~Participant() {
  if (participant_ == nullptr) return;
  // Readers first: once they are gone no listener callback can still write with a writer deleted below.
  subscriber_->delete_contained_entities();
  participant_->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(participant_);
}

Topic* Participant::topic(const std::string& name, TopicDataType* type) {
  TypeSupport support(type);  // owns `type` from here on whichever way this returns (it leaked when the topic existed)
  auto it = topics_.find(name);
  if (it != topics_.end()) return it->second;
  if (participant_->find_type(support.get_type_name()) == nullptr) support.register_type(participant_);
  Topic* t = participant_->create_topic(name, support.get_type_name(), TOPIC_QOS_DEFAULT);
  if (t == nullptr) throw std::runtime_error("cannot create DDS topic " + name);
  topics_[name] = t;
  return t;
}

DataWriter* Participant::writer(Topic* topic, const std::string& profile, DataWriterListener* listener) {
  DataWriter* w = publisher_->create_datawriter_with_profile(topic, profile, listener);
  if (w == nullptr) {
    throw std::runtime_error("cannot create a DDS writer on " + topic->get_name() + " with profile '" + profile +
                             "' (is the profiles file loaded?)");
  }
  return w;
}

DataReader* Participant::reader(Topic* topic, const std::string& profile, DataReaderListener* listener) {
  DataReader* r = subscriber_->create_datareader_with_profile(topic, profile, listener);
  if (r == nullptr) {
    throw std::runtime_error("cannot create a DDS reader on " + topic->get_name() + " with profile '" + profile +
                             "' (is the profiles file loaded?)");
  }
  return r;
}

}  // namespace surgsim::dds
