/* hapticlab's stand-in for OpenHaptics' HD API: the servo scheduler, with OpenHaptics 3.0's
 * types and signatures. */
#ifndef HL_STUB_HD_SCHEDULER_H
#define HL_STUB_HD_SCHEDULER_H

#include <HD/hdExport.h>
#include <HD/hdCompilerConfig.h>
#include <HD/hdDefines.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef unsigned int HDCallbackCode;
#define HD_CALLBACK_DONE 0
#define HD_CALLBACK_CONTINUE 1
typedef unsigned long HDSchedulerHandle;
typedef HDCallbackCode (HDCALLBACK *HDSchedulerCallback)(void *pUserData);

HDAPI void HDAPIENTRY hdStartScheduler();
HDAPI void HDAPIENTRY hdStopScheduler();
HDAPI void HDAPIENTRY hdSetSchedulerRate(HDulong nRate);
/* runs pCallback once in the scheduler's thread and waits for it */
HDAPI void HDAPIENTRY hdScheduleSynchronous(HDSchedulerCallback pCallback, void *pUserData,
                                            HDushort nPriority);
/* runs pCallback at every tick of the scheduler's thread until it returns HD_CALLBACK_DONE */
HDAPI HDSchedulerHandle HDAPIENTRY hdScheduleAsynchronous(HDSchedulerCallback pCallback,
                                                          void *pUserData, HDushort nPriority);
HDAPI void HDAPIENTRY hdUnschedule(HDSchedulerHandle hHandle);

#ifdef __cplusplus
}
#endif

#endif
