# Issue 18: the web view. The frame stream (JPEG round trip, size bound, drop when busy, scene keys), surgsim-web's
# rules (routes, tokens, messages, the virtual device, one driver), its refusals against the real server, and a real
# headless chromium (python3-selenium, chromium-driver) against the three real processes.
if(SURGSIM_BUILD_VISUAL)
  surgsim_test(visual_frame_stream_test SOURCES visual_node/frame_stream_test.cpp LIBS surgsim_visual)
  surgsim_test(web_logic_test SOURCES visual_node/web/web_logic_test.cpp LIBS surgsim_web)

  add_test(NAME web_requests_test
    COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/integration/web_requests_test.py ${CMAKE_BINARY_DIR}/bin
            ${SURGSIM_SOURCE_DIR}/config ${CMAKE_BINARY_DIR}/web_test/requests)
  set_tests_properties(web_requests_test PROPERTIES TIMEOUT 60)
  foreach(case watch drive)
    add_test(NAME web_browser_${case}_test
      COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/integration/web_browser_test.py ${case}
              ${CMAKE_BINARY_DIR}/bin ${SURGSIM_SOURCE_DIR}/config ${CMAKE_BINARY_DIR}/cache
              ${CMAKE_BINARY_DIR}/web_test/${case})
    # One browser test at a time (two chromiums and three nodes each on 2 cores).
    set_tests_properties(web_browser_${case}_test PROPERTIES TIMEOUT 120 RESOURCE_LOCK surgsim_web_browser)
  endforeach()
  add_custom_target(web_test_programs DEPENDS haptic_node visual_node surgsim_web_app)
endif()

# frame_bench: JPEG encode time and size per resolution and quality, the render loop's share (issue 18).
if(SURGSIM_BUILD_VISUAL AND SURGSIM_BUILD_BENCHMARKS)
  surgsim_bench(frame_bench SOURCES bench/frame_bench.cpp LIBS surgsim_visual)
endif()

# scripts/run_local.sh liver --web: three processes, the URL printed, frames and contact frames through surgsim-web.
if(SURGSIM_BUILD_VISUAL)
  add_test(NAME web_run_local_test
    COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/integration/web_run_local_test.sh ${SURGSIM_SOURCE_DIR} ${CMAKE_BINARY_DIR}
            ${CMAKE_BINARY_DIR}/web_test/run_local)
  set_tests_properties(web_run_local_test PROPERTIES TIMEOUT 90)
endif()
