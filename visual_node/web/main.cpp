// surgsim-web: watch and drive the simulator from a browser. Joins the DDS domain, serves one page over
// HTTP + WebSocket (web_server.h) with the visual node's live frames, the force, contacts, rates and the scene, and a
// virtual device that publishes one instrument's ToolCommand while a page drives it.
#include <CLI/CLI.hpp>
#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>

#include "core/stats.h"
#include "dds_support.h"
#include "scene/scene.h"
#include "tool/trajectory.h"
#include "web_dds.h"
#include "web_server.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::scene;

#ifndef SURGSIM_WEB_ROOT
#define SURGSIM_WEB_ROOT "visual_node/web/www"
#endif

int main(int argc, char** argv) {
  using namespace surgsim;
  web::ServerOptions o;
  std::string scene_name = "liver";
  std::string instrument_name;
  std::string stats_file;
  double duration = -1;
  int domain = -1;
  std::string dds_profiles, dds_participant;
  o.www = SURGSIM_WEB_ROOT;
  CLI::App cli{"surgsim-web: serves one page (live view, force and contact plots, scene, and a virtual device that "
               "drives one instrument) over HTTP + WebSocket, bridged to the simulator's DDS topics. Binds 127.0.0.1 "
               "unless --bind says otherwise; the URL it prints carries a random token, required for the page, the "
               "WebSocket and /stats. Open it from another machine through SSH: ssh -L 8080:127.0.0.1:8080 HOST, "
               "then the printed URL."};
  cli.add_option("--scene", scene_name, "Scene YAML file or shipped scene name (the instrument's range and start "
                 "pose)")->capture_default_str();
  cli.add_option("--instrument", instrument_name, "Name of the instrument the page drives (default: the scene's "
                 "first)");
  cli.add_option("--bind", o.bind, "Address to listen on (127.0.0.1: this machine only; 0.0.0.0: every interface)")
      ->capture_default_str();
  cli.add_option("--port", o.port, "TCP port (0: any free port)")->check(CLI::Range(0, 65535))->capture_default_str();
  cli.add_option("--token", o.token, "Token required in the URL (default: 32 random hex digits)");
  cli.add_option("--www", o.www, "Folder of the page's files (index.html, app.js, style.css)")->capture_default_str();
  cli.add_option("--command-rate", o.command_rate_hz, "ToolCommand rate while a page drives, Hz")
      ->check(CLI::Range(20.0, 1000.0))->capture_default_str();
  cli.add_option("--max-clients", o.max_clients, "Pages connected at once")->check(CLI::Range(1, 64))
      ->capture_default_str();
  cli.add_option("--max-connections", o.max_connections,
                 "Open connections at once (at most what the open-file limit leaves); beyond, the oldest whose "
                 "request did not carry the token is closed")
      ->check(CLI::Range(16, 1 << 20))
      ->capture_default_str();
  cli.add_option("--max-message", o.max_ws_message, "Largest WebSocket message a page may send, bytes")
      ->check(CLI::Range(256, 1 << 20))->capture_default_str();
  cli.add_option("--duration", duration, "Stop after S seconds (default: until SIGINT/SIGTERM)");
  cli.add_option("--stats", stats_file, "Write a JSON summary here on exit (what /stats shows)");
  cli.add_option("--domain", domain, "DDS domain id (default $SURGSIM_DOMAIN or 0)");
  cli.add_option("--dds-profiles", dds_profiles, "Fast DDS XML profiles file (default config/dds/profiles.xml)");
  cli.add_option("--dds-participant", dds_participant, "Participant profile (default $SURGSIM_DDS_PARTICIPANT or "
                 "surgsim_default)");
  cli.add_flag("--quiet", o.quiet, "Print only the URL and errors");
  CLI11_PARSE(cli, argc, argv);

  try {
    // --- init: the scene's instrument (range, start pose) ---
    const Scene scene = load_scene(resolve_scene_path(scene_name));
    int index = 0;
    if (!instrument_name.empty()) {
      index = -1;
      std::string names;
      for (std::size_t i = 0; i < scene.tools.size(); ++i) {
        if (scene.tools[i].name == instrument_name) index = static_cast<int>(i);
        names += (i ? ", " : "") + scene.tools[i].name;
      }
      if (index < 0) {
        std::cerr << "surgsim-web: --instrument '" << instrument_name << "' is not in scene '" << scene.name << "' ("
                  << scene.file << "); its instruments: " << names << "\n";
        return 2;
      }
    }
    const ToolSpec& tool = scene.tools[static_cast<std::size_t>(index)];
    o.instrument = static_cast<std::uint32_t>(index);
    o.instrument_name = tool.name;
    o.scene = scene.name;
    o.limits.max_insertion = tool.shaft_length;
    o.force_limit = tool.force_limit;
    // Start where the scene's trajectory starts (above the organ), else at the trocar.
    if (!scene.trajectory.empty()) {
      const MultiTrajectory traj = MultiTrajectory::load(scene.trajectory);
      int i = traj.find(tool.name);
      if (i < 0 && traj.instruments() == 1) i = 0;
      if (i >= 0 && traj.size() > 0) traj.at(i, 0.0, o.start_pose);
    }
    if (o.token.empty()) o.token = web::random_token();
    if (o.token.find_first_not_of("0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ-_") !=
            std::string::npos ||
        o.token.size() < 8) {
      std::cerr << "surgsim-web: --token '" << o.token << "' must be at least 8 characters of 0-9, a-z, A-Z, - and _ "
                << "(it goes into a URL)\n";
      return 2;
    }

    // --- init: DDS, then the server ---
    surgsim::dds::DdsOptions dopt;
    dopt.domain = domain >= 0 ? domain : surgsim::dds::default_domain();
    dopt.profiles_file = dds_profiles.empty() ? config_dir() + "/dds/profiles.xml" : dds_profiles;
    dopt.participant_profile = dds_participant;
    dopt.name = "surgsim_web";
    web::WebDds bridge(dopt, o.instrument);
    web::WebServer server(o, bridge);
    if (!o.quiet) {
      std::cerr << "surgsim-web: scene '" << scene.name << "', driving instrument " << o.instrument << " '"
                << tool.name << "' at " << o.command_rate_hz << " Hz while a page drives; DDS "
                << bridge.participant().profile() << "\n";
      if (!web::is_loopback(o.bind)) {
        std::cerr << "surgsim-web: listening on " << o.bind << ": anyone who can reach this port and has the token "
                  << "can drive the tool\n";
      }
    }
    std::cout << "surgsim-web: open " << server.url() << std::endl;

    // --- run, then shutdown ---
    server.run(duration);
    if (!stats_file.empty()) write_json_file(stats_file, server.stats());
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "surgsim-web: " << e.what() << "\n";
    return 1;
  }
}
